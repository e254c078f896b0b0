"""FMI layer: the generic pythonfmu adapter, the builder, the modelDescription post-processing."""
