"""The pythonfmu model scripts, one per controller FMU (``ncfmu build`` turns each into ``fmus/<Name>.fmu``).

Installed with ncfmu as the package ``ncfmu.models``, so a wheel builds its FMUs without a checkout.
"""
