"""Documentation generated from the artefacts themselves.

- ``docs/fmus/<Model>.md`` (the page every FMU carries, :mod:`ncfmu.fmi.documentation`) and
  ``docs/systems/<system>.md``, written by ``ncfmu build``.
"""

from __future__ import annotations

from pathlib import Path

from .fmi.documentation import fmu_markdown


def system_markdown(system) -> str:
    lines = [f"# {system.name}", "", system.description, "",
             f"Default experiment: 0 .. {system.stop_time:g} s, step {system.step_size:g} s. "
             f"Run it: `ncfmu run {system.name}`; in libcosim: `ssp/{system.name}.ssp`.", "",
             "## Components (stepped in this order)", "", "| instance | FMU | parameters set by the system |",
             "|---|---|---|"]
    for c in system.components:
        params = ", ".join(f"`{k}={v}`" for k, v in c.parameters.items())
        lines.append(f"| `{c.name}` | [{c.model}](../fmus/{c.model}.md) | {params} |")
    lines += ["", "## Connections", ""]
    lines += [f"- `{k.start_element}.{k.start_connector}` -> `{k.end_element}.{k.end_connector}`"
              for k in system.connections]
    return "\n".join(lines) + "\n"


def write_docs(root: Path, fmus: list[Path]) -> list[Path]:
    """Write docs/fmus/*.md from the built FMUs and docs/systems/*.md from the system definitions."""
    import zipfile

    from .files import write_if_changed
    from .systems import MODELS, SYSTEMS, get_system
    written = []
    (root / "docs" / "fmus").mkdir(parents=True, exist_ok=True)
    (root / "docs" / "systems").mkdir(parents=True, exist_ok=True)
    for fmu in fmus:
        with zipfile.ZipFile(fmu) as z:
            md = z.read("modelDescription.xml")
        logic = MODELS[fmu.stem]
        path = root / "docs" / "fmus" / f"{fmu.stem}.md"
        write_if_changed(path, fmu_markdown(md, logic).encode())
        written.append(path)
    for name in SYSTEMS:
        path = root / "docs" / "systems" / f"{name}.md"
        write_if_changed(path, system_markdown(get_system(name)).encode())
        written.append(path)
    return written
