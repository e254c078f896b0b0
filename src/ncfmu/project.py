"""The project on disk (``models/``, ``fmus/``, ``ssp/``): build everything, open and run systems.

This is the API behind the command line::

    from ncfmu.project import simulate
    result = simulate("lathe_roughing", start_values={"seq.block[1].Xd": 0.4})
    result["x_axis.pos"]
"""

from __future__ import annotations

import shutil
import tempfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from .cosim.fmu import FmuSlave, UnpackedFmu, safe_extract, unpacked_fmu
from .cosim.master import InputTable, Master, Session, steps_per_row
from .cosim.native_loop import build_library
from .cosim.record import EveryKth, RecordSink, SelectColumns
from .cosim.result import Result
from .cosim.ssp import SSD_NAME, System, fmu_path, pack, read_ssp, write_system
from .errors import SystemDefinitionError
from .files import is_checkout, project_root
from .fmi.builder import build_all
from .systems import SYSTEMS, get_system, report_for
from .systems.report import ReportAccumulator, start_parameters


def models_dir(root: Path) -> Path:
    """The model scripts: the checkout's ``models/``, else the copy the wheel carries (``ncfmu.models``)."""
    if (root / "models" / "CutSequencer.py").is_file():
        return root / "models"
    import importlib
    packaged = importlib.import_module("ncfmu.models")      # mapped from models/ by pyproject, not in src/
    return Path(str(packaged.__file__)).parent


def build(root: Path | None = None, only_stale: bool = True) -> dict[str, list[Path]]:
    """Build every FMU into ``fmus/``, write every system to ``ssp/<system>/`` and pack ``ssp/<system>.ssp``;
    in a checkout also write ``docs/``. Nothing whose content is already right is touched."""
    root = Path(root or project_root())
    (root / "fmus").mkdir(parents=True, exist_ok=True)
    fmus = build_all(models_dir(root), root / "fmus", only_stale=only_stale)
    if is_checkout(root):
        from .docs import write_docs
        write_docs(root, fmus)
    build_library(root)                     # the master's C loop, next to the FMUs it drives
    archives = []
    for name in SYSTEMS:
        folder = write_system(get_system(name), root / "ssp")
        archives.append(pack(folder, root / "fmus", root / "ssp" / f"{name}.ssp"))
    return {"fmus": fmus, "ssp": archives}


def system_archive(system: str, root: Path | None = None, ensure_built: bool = True) -> Path:
    """Path of a system's .ssp: a file path as given, or ``ssp/<name>.ssp`` (built when missing or stale)."""
    p = Path(system)
    if p.suffix == ".ssp":
        if not p.is_file():
            raise SystemDefinitionError(f"SSP archive not found: {p}")
        return p
    if system not in SYSTEMS:
        raise SystemDefinitionError(f"unknown system {system!r}; known systems: {', '.join(SYSTEMS)} "
                                    "(or give the path of an .ssp file)")
    root = Path(root or project_root())
    if ensure_built:
        build(root, only_stale=True)
    return root / "ssp" / f"{system}.ssp"


class OpenSystem:
    """An .ssp archive unpacked once, its FMUs instantiated through fmpy, ready to run."""

    def __init__(self, archive: Path, mode: str = "gauss-seidel") -> None:
        self.archive = Path(archive)
        self._tmp = Path(tempfile.mkdtemp(prefix="ncfmu_ssp_"))
        try:
            # read from the archive first: every component's source is checked before anything is extracted
            self.system: System = read_ssp(self.archive)
            folder = safe_extract(self.archive, self._tmp / "ssp")
            self.unpacked: dict[str, UnpackedFmu] = {}
            for comp in self.system.components:
                if comp.model not in self.unpacked:
                    self.unpacked[comp.model] = unpacked_fmu(fmu_path(folder, comp, self.archive))
            self.slaves = [FmuSlave(self.unpacked[c.model], c.name) for c in self.system.components]
            self.master = Master(self.system, self.slaves, mode)
        except Exception:
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise

    def run(self, **kwargs) -> Result:
        """One run from start to stop (:meth:`Master.run <ncfmu.cosim.master.Master.run>`)."""
        return self.master.run(**kwargs)

    def open_session(self, **kwargs) -> Session:
        """A run stepped from outside (:meth:`Master.open_session <ncfmu.cosim.master.Master.open_session>`)."""
        return self.master.open_session(**kwargs)

    def close(self) -> None:
        try:
            self.master.terminate()
        finally:
            shutil.rmtree(self._tmp, ignore_errors=True)

    def __enter__(self) -> OpenSystem:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass
class Recording:
    """How a run records: the outputs it records, the sinks its rows go to, the interval the run itself records
    at, and the report's metrics computed as it goes. Made one way (:func:`recording`) for every front end."""

    record: list[str] | None
    sinks: list[RecordSink]
    output_interval: float | None
    summary: ReportAccumulator | None

    def run_arguments(self) -> dict[str, object]:
        """The arguments of ``Master.run`` / ``open_session`` that say what is recorded and where it goes."""
        return {"record": self.record, "sinks": self.sinks, "output_interval": self.output_interval}


def recording(system: System, start_values: Mapping[str, object], rows: RecordSink | None = None,
              columns: Sequence[str] | None = None, output_interval: float | None = None,
              step_size: float | None = None, summary: bool = True, every: int | None = None) -> Recording:
    """What a run of ``system`` records: ``rows`` (a CSV, any sink) gets ``columns`` (default every output) every
    ``output_interval`` s; with ``summary`` the system's report reads every step of what it needs (its accumulator,
    made for the run's parameters: the system's sets with ``start_values`` on top) while the run records only those
    columns and ``columns``. Without ``summary`` the run itself records ``columns`` at ``output_interval``.
    ``every``: the rows' spacing in steps, instead of ``output_interval``."""
    record = None if columns is None else list(dict.fromkeys(columns))
    if not summary:
        return Recording(record, [] if rows is None else [rows], output_interval, None)
    report = report_for(system.name, {c.name: c.model for c in system.components})
    accumulator = report.accumulator(start_parameters(system.components, start_values))
    run_record = None if record is None else list(dict.fromkeys([*record, *report.record()]))
    sinks: list[RecordSink] = []
    if rows is not None:
        view = rows if run_record == record else SelectColumns(rows, record or [])
        if every is None:
            every = steps_per_row(output_interval, system.step_size if step_size is None else step_size)
        sinks.append(view if every == 1 else EveryKth(view, every))
    return Recording(run_record, [*sinks, accumulator], None, accumulator)


def simulate(system: str = "lathe_roughing", stop_time: float | None = None, step_size: float | None = None,
             start_values: Mapping[str, object] | None = None, input_csv: Path | None = None,
             mode: str = "gauss-seidel", root: Path | None = None, progress=None,
             record: Sequence[str] | None = None, output_interval: float | None = None,
             sinks: Sequence[RecordSink] = (), keep: bool = True) -> Result:
    """Build what is missing, run ``system`` (a name or an .ssp path) closed loop, return the result.

    ``record``, ``output_interval``, ``sinks`` and ``keep`` as :meth:`~ncfmu.cosim.master.Master.run`: e.g.
    ``sinks=[CsvSink("out/run.csv")], keep=False`` streams a run of any length to disk at flat memory."""
    archive = system_archive(system, root)
    inputs = InputTable.from_csv(input_csv) if input_csv else None
    with OpenSystem(archive, mode) as opened:
        return opened.run(stop_time=stop_time, step_size=step_size, start_values=start_values,
                          inputs=inputs, progress=progress, record=record, output_interval=output_interval,
                          sinks=sinks, keep=keep)


@dataclass(frozen=True)
class Validation:
    """What :func:`validation` checked, and the problems it found."""

    problems: list[str]
    root: Path
    fmus: int
    systems: int
    parameter_sets: int

    def checked(self) -> list[str]:
        """What was checked, in words."""
        return [f"{self.fmus} FMUs ({self.root / 'fmus'}) with fmpy.validation: modelDescription.xml against the "
                "FMI 2.0 schema, unique and valid variable names, a complete ModelStructure, the required start "
                "values, causality/variability combinations, units; no backslash in a file path",
                f"{self.systems} systems ({self.root / 'ssp'}/<system>.ssp): SystemStructure.ssd against the SSP 1.0 "
                "schema (fmpy) and one flat ssd:System with literal prefixes (as libcosim reads it); their "
                f"{self.parameter_sets} .ssv parameter sets against the SSP 1.0 parameter-values schema"]


def validate(root: Path | None = None) -> list[str]:
    """Check every FMU with fmpy and every system with fmpy's SSP 1.0 schema; return the problems."""
    return validation(root).problems


def validation(root: Path | None = None) -> Validation:
    """Check every FMU with fmpy and every system with fmpy's SSP 1.0 schema: what was checked, what failed."""
    import zipfile

    from fmpy.ssp.ssd import read_ssd as fmpy_read_ssd
    from fmpy.ssp.ssd import read_ssv as fmpy_read_ssv
    from fmpy.validation import validate_fmu

    root = Path(root or project_root())
    build(root, only_stale=True)
    problems = []
    fmus = sorted((root / "fmus").glob("*.fmu"))
    n_ssv = 0
    for fmu in fmus:
        for p in validate_fmu(str(fmu)):
            problems.append(f"{fmu}: {p}")
    for name in SYSTEMS:
        archive = root / "ssp" / f"{name}.ssp"
        try:
            fmpy_read_ssd(str(archive), validate=True)
        except Exception as err:  # fmpy raises plain exceptions for schema violations
            problems.append(f"{archive}: SystemStructure.ssd breaks the SSP 1.0 schema: {err}")
        with zipfile.ZipFile(archive) as z:
            ssd_text = z.read(SSD_NAME).decode()
            ssvs = [n for n in z.namelist() if n.endswith(".ssv")]
        n_ssv += len(ssvs)
        if "<ssd:SystemStructureDescription" not in ssd_text or ssd_text.count("<ssd:System ") != 1:
            problems.append(f"{archive}: SystemStructure.ssd must be one flat ssd:System with literal prefixes "
                            "(libcosim reads the prefixes literally)")
        for ssv in ssvs:
            try:
                fmpy_read_ssv(str(archive), resource=ssv, validate=True)
            except Exception as err:
                problems.append(f"{archive}: {ssv} breaks the SSP 1.0 parameter-values schema: {err}")
    return Validation(problems, root, len(fmus), len(SYSTEMS), n_ssv)


def simulate_branches(system: str, branch_time: float, variants: Sequence[Mapping[str, object]],
                      stop_time: float | None = None, start_values: Mapping[str, object] | None = None,
                      mode: str = "gauss-seidel", root: Path | None = None) -> list[Result]:
    """Run ``system`` to ``branch_time`` once, then every variant from the saved FMU states.

    >>> simulate_branches("grinder_feed", 10.0, [{"panel.emergency_at": t} for t in (12.0, 21.0, 31.0)])
    """
    archive = system_archive(system, root)
    with OpenSystem(archive, mode) as opened:
        return opened.master.run_branches(branch_time, variants, stop_time=stop_time, start_values=start_values)
