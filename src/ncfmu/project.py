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
from typing import Any

from .cosim.connect import free_inputs
from .cosim.fmu import UnpackedFmu, safe_extract, unpacked_fmu
from .cosim.instances import make_slave
from .cosim.master import InputTable, Master, Session, steps_per_row
from .cosim.native_loop import build_library
from .cosim.record import EveryKth, RecordSink, SelectColumns
from .cosim.result import Result
from .cosim.slave import ResettableSlave
from .cosim.ssp import SSD_NAME, Component, System, fmu_path, pack, read_ssd, read_ssp, write_system
from .errors import SystemDefinitionError
from .files import is_checkout, project_root
from .fmi.builder import build_all, chosen_pure, remember_kind
from .fmi.fmi3 import build_all_fmi3
from .systems import SYSTEMS, get_system, report_for
from .systems.report import Report, ReportAccumulator, start_parameters
from .systems.roles import identify


def shipped(system: System, models: Mapping[str, str] | None = None) -> bool:
    """Whether ``system`` is one ncfmu ships, as it ships it (its name, instances and models): its free inputs are
    meant to be free (a servo's enable, a single-axis grinder's second axis)."""
    if system.name not in SYSTEMS:
        return False
    own = get_system(system.name)
    return ({c.name: c.model for c in own.components} == dict(models or {c.name: c.model for c in system.components})
            and {str(c) for c in own.connections} == {str(c) for c in system.connections})


def models_dir(root: Path) -> Path:
    """The model scripts: the checkout's ``models/``, else the copy the wheel carries (``ncfmu.models``)."""
    if (root / "models" / "CutSequencer.py").is_file():
        return root / "models"
    import importlib
    packaged = importlib.import_module("ncfmu.models")      # mapped from models/ by pyproject, not in src/
    return Path(str(packaged.__file__)).parent


def build(root: Path | None = None, only_stale: bool = True, pure: bool | None = None) -> dict[str, list[Path]]:
    """Build every FMU into ``fmus/``, write every system to ``ssp/<system>/`` and pack ``ssp/<system>.ssp``;
    in a checkout also write ``docs/``. Nothing whose content is already right is touched. ``pure``: True, the
    Python FMUs without their compiled controllers; False, compiled with mypyc where it can be (once, cached);
    None, the kind the last build into ``fmus/`` was asked for (``fmus/ncfmu-build-kind``), else compiled. The
    kind asked for is recorded there, so it sticks until asked otherwise."""
    root = Path(root or project_root())
    (root / "fmus").mkdir(parents=True, exist_ok=True)
    pure = chosen_pure(root / "fmus", pure)
    remember_kind(root / "fmus", pure)
    fmus = build_all(models_dir(root), root / "fmus", only_stale=only_stale, pure=pure)
    fmus3 = build_all_fmi3(fmus, root / "fmus" / "fmi3", only_stale=only_stale)    # their FMI 3.0 twins
    if is_checkout(root):
        from .docs import write_docs
        write_docs(root, fmus)
    build_library(root)                     # the master's C loop, next to the FMUs it drives
    archives = []
    for name in SYSTEMS:
        folder = write_system(get_system(name), root / "ssp")
        archives.append(pack(folder, root / "fmus", root / "ssp" / f"{name}.ssp"))
    return {"fmus": fmus, "fmi3": fmus3, "ssp": archives}


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


def model_descriptions(archive: Path, system: System) -> dict[str, bytes]:
    """instance -> its FMU's modelDescription.xml, read from the .ssp archive (nothing extracted or loaded)."""
    import zipfile
    out = {}
    with zipfile.ZipFile(archive) as z:
        for comp in system.components:
            try:
                with zipfile.ZipFile(z.open(comp.source)) as fmu:
                    out[comp.name] = fmu.read("modelDescription.xml")
            except (KeyError, zipfile.BadZipFile) as err:
                raise SystemDefinitionError(f"{archive}: {comp.source} has no readable modelDescription.xml "
                                            f"({err})") from None
    return out


def report_scales(archive: Path, system: System, columns: Sequence[str]) -> dict[str, float]:
    """The factor that brings each of ``columns`` (``INSTANCE.VARIABLE``) into mm where its FMU records it in
    another length unit (a user's axis in m): the reports and plots are in mm, the CSV keeps the FMU's units."""
    from fmpy import read_model_description

    from .cosim.units import Unit, conversion, unit_from_fmpy, variable_unit
    mm = Unit.of("mm", {"m": 1}, 1e-3)
    scales: dict[str, float] = {}
    wanted: dict[str, list[str]] = {}
    for column in columns:
        inst, _, var = column.partition(".")
        wanted.setdefault(inst, []).append(var)
    described = model_descriptions(archive, system) if wanted else {}
    for inst, names in wanted.items():
        md_xml = described.get(inst)
        if md_xml is None or identify(md_xml).model:        # one of ncfmu's models: in mm by its ports
            continue
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / "modelDescription.xml").write_bytes(md_xml)
            md = read_model_description(str(Path(tmp) / "modelDescription.xml"))
        variables = {v.name: v for v in md.modelVariables}
        for var in names:
            unit = variable_unit(variables[var]) if var in variables else None
            if unit and unit != "mm":
                conv = conversion(unit_from_fmpy(unit, md.unitDefinitions), mm)
                if conv is not None and not conv.identity and conv.offset == 0:
                    scales[f"{inst}.{var}"] = conv.gain
    return scales


class ScaledSink:
    """A recording sink that hands ``sink`` the rows with some columns multiplied (:func:`report_scales`)."""

    def __init__(self, sink: RecordSink, scales: Mapping[str, float]) -> None:
        self.sink, self.scales = sink, dict(scales)

    def open(self, columns) -> None:
        self.scales = {k: v for k, v in self.scales.items() if k in {name for name, _ in columns}}
        self.sink.open(columns)

    def write(self, rows) -> None:
        if self.scales:
            rows = rows.copy()
            for name, gain in self.scales.items():
                rows[name] *= gain
        self.sink.write(rows)

    def close(self, complete: bool, stopped_at: float | None = None, reason: str = "") -> None:
        self.sink.close(complete, stopped_at, reason)


def plant_axes(archive: Path, system: System, models: Mapping[str, str]) -> list[str]:
    """The axes of ``system`` by their role (:func:`~ncfmu.systems.roles.axes`) whose FMU has the outputs a report
    reads of an axis (``pos``, ``following_error``)."""
    import xml.etree.ElementTree as ET

    from .systems.roles import axes
    described = model_descriptions(archive, system)
    found = []
    for inst in axes(system, models):
        root = ET.fromstring(described[inst])
        outputs = {v.get("name") for v in root.iter() if v.get("causality") == "output"}
        if {"pos", "following_error"} <= outputs:
            found.append(inst)
    return found


def archive_models(archive: Path, system: System) -> dict[str, str]:
    """instance -> the catalogue model its FMU is, or ``foreign:<modelName>`` (by its modelDescription)."""
    return {inst: i.model or f"foreign:{i.model_name}"
            for inst, i in ((inst, identify(md, f"{archive}: {inst}"))
                            for inst, md in model_descriptions(archive, system).items())}


class OpenSystem:
    """An .ssp archive unpacked once, its FMUs instantiated through fmpy, ready to run."""

    def __init__(self, archive: Path, mode: str = "gauss-seidel", isolate: bool = True) -> None:
        """``isolate``: each foreign FMU (not one of ncfmu's models) in a process of its own
        (:mod:`~ncfmu.cosim.isolated`); False runs it in this process, as ncfmu's own."""
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
            #: instance -> what its FMU is, from its modelDescription (never the file name)
            self.identities = {c.name: identify((self.unpacked[c.model].directory / "modelDescription.xml")
                                                .read_bytes(), f"{self.archive}: {c.source}")
                               for c in self.system.components}
            # a foreign FMU runs in a process of its own: its crash ends the run with an error, not the process
            self.slaves: list[ResettableSlave] = []
            for c in self.system.components:
                unpacked = self.unpacked[c.model]
                if self.identities[c.name].model or not isolate:
                    self.slaves.append(make_slave(unpacked, c.name))
                else:
                    from .cosim.isolated import isolated_slave
                    self.slaves.append(isolated_slave(unpacked, c.name))
            self.master = Master(self.system, self.slaves, mode)
        except Exception:
            for slave in getattr(self, "slaves", ()):
                slave.terminate()           # an isolated one's process ends with it
            shutil.rmtree(self._tmp, ignore_errors=True)
            raise

    def warnings(self, start_values: Mapping[str, object] | None = None, inputs: InputTable | None = None) -> list[str]:
        """The system's warning lines: the master's (units), and for a system ncfmu does not ship as it is, every
        input nothing drives and no value is given for."""
        lines = list(self.master.warnings)
        if not shipped(self.system, self.models):
            given = set(start_values or {}) | set(inputs.columns if inputs is not None else {})
            given |= self._free_by_design()
            lines += free_inputs(self.system, self.master.by_name, given)
        return lines

    def _free_by_design(self) -> set[str]:
        """The inputs the shipped system of this name leaves free on purpose, of instances that kept their model
        (a servo's enable, the panel's m_active): not worth a warning in a variant of it."""
        if self.system.name not in SYSTEMS:
            return set()
        own = get_system(self.system.name)
        driven = {(c.end_element, c.end_connector) for c in own.connections}
        models = self.models
        from .systems.compose import MODELS
        return {f"{c.name}.{p.name}" for c in own.components if models.get(c.name) == c.model
                for p in MODELS[c.model].PORTS if p.causality == "input" and (c.name, p.name) not in driven}

    def report(self) -> Report:
        """The system's report, by what its FMUs are (a user's plant: its axes found in it)."""
        return report_for(self.system.name, self.models, plant_axes(self.archive, self.system, self.models))

    @property
    def models(self) -> dict[str, str]:
        """instance -> the catalogue model its FMU is, or ``foreign:<modelName>``."""
        return {inst: i.model or f"foreign:{i.model_name}" for inst, i in self.identities.items()}

    def run(self, **kwargs) -> Result:
        """One run from start to stop (:meth:`Master.run <ncfmu.cosim.master.Master.run>`), with the system's
        warnings and what each instance's FMU is."""
        result = self.master.run(**kwargs)
        result.warnings = self.warnings(kwargs.get("start_values"), kwargs.get("inputs"))
        result.models = self.models
        return result

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
    at, the system's report and its metrics computed as the run goes, and the factors that bring a user's axis
    into the report's mm. Made one way (:func:`recording`) for every front end."""

    record: list[str] | None
    sinks: list[RecordSink]
    output_interval: float | None
    report: Report
    summary: ReportAccumulator | None
    scales: dict[str, float]

    def run_arguments(self) -> dict[str, object]:
        """The arguments of ``Master.run`` / ``open_session`` that say what is recorded and where it goes."""
        return {"record": self.record, "sinks": self.sinks, "output_interval": self.output_interval}


def recording(opened: OpenSystem, start_values: Mapping[str, object], rows: RecordSink | None = None,
              columns: Sequence[str] | None = None, output_interval: float | None = None,
              step_size: float | None = None, summary: bool = True, every: int | None = None,
              in_mm: bool = False, report: Report | None = None) -> Recording:
    """What a run of the ``opened`` system records: ``rows`` (a CSV, any sink) gets ``columns`` (default every
    output) every ``output_interval`` s (or ``every`` steps); with ``summary`` the system's report (by what its FMUs
    are) reads every step of what it needs -- its accumulator, made for the run's parameters: the system's sets with
    ``start_values`` on top -- while the run records only those columns and ``columns``. Without ``summary`` the run
    itself records ``columns`` at ``output_interval``. ``in_mm``: the report reads a user's axis recorded in another
    length unit in mm (:func:`report_scales`; the rows keep the FMU's units). ``report``: another report than
    the system's own (the system's with the part check's settings, say)."""
    system = opened.system
    report = opened.report() if report is None else report
    scales = report_scales(opened.archive, system, report.record()) if in_mm else {}
    record = None if columns is None else list(dict.fromkeys(columns))
    if not summary:
        return Recording(record, [] if rows is None else [rows], output_interval, report, None, scales)
    accumulator = report.accumulator(start_parameters(system.components, start_values))
    run_record = None if record is None else list(dict.fromkeys([*record, *report.record()]))
    sinks: list[RecordSink] = []
    if rows is not None:
        view = rows if run_record == record else SelectColumns(rows, record or [])
        if every is None:
            every = steps_per_row(output_interval, system.step_size if step_size is None else step_size)
        sinks.append(view if every == 1 else EveryKth(view, every))
    sinks.append(ScaledSink(accumulator, scales) if scales else accumulator)
    return Recording(run_record, sinks, None, report, accumulator, scales)


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
    fmus3: int = 0

    def checked(self) -> list[str]:
        """What was checked, in words."""
        return [f"{self.fmus} FMUs ({self.root / 'fmus'}) with fmpy.validation: modelDescription.xml against the "
                "FMI 2.0 schema, unique and valid variable names, a complete ModelStructure, the required start "
                "values, causality/variability combinations, units; no backslash in a file path",
                f"{self.fmus3} FMI 3.0 FMUs ({self.root / 'fmus' / 'fmi3'}) with fmpy.validation: "
                "modelDescription.xml against the FMI 3.0 schema, the same rules",
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
    fmus3 = sorted((root / "fmus" / "fmi3").glob("*.fmu"))       # their FMI 3.0 twins, validated as FMI 3.0
    n_ssv = 0
    for fmu in [*fmus, *fmus3]:
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
    return Validation(problems, root, len(fmus), len(SYSTEMS), n_ssv, len(fmus3))


def simulate_branches(system: str, branch_time: float, variants: Sequence[Mapping[str, object]],
                      stop_time: float | None = None, start_values: Mapping[str, object] | None = None,
                      mode: str = "gauss-seidel", root: Path | None = None) -> list[Result]:
    """Run ``system`` to ``branch_time`` once, then every variant from the saved FMU states.

    >>> simulate_branches("grinder_feed", 10.0, [{"panel.emergency_at": t} for t in (12.0, 21.0, 31.0)])
    """
    archive = system_archive(system, root)
    with OpenSystem(archive, mode) as opened:
        return opened.master.run_branches(branch_time, variants, stop_time=stop_time, start_values=start_values)


# -- a user's system: a bare FMU, an .ssd with its folder, an unpacked folder; components replaced; packed --------
_WORK: list[Path] = []


def _workdir() -> Path:
    """A folder of this process for the archives made from a user's sources (removed at exit)."""
    if not _WORK:
        import atexit
        _WORK.append(Path(tempfile.mkdtemp(prefix="ncfmu_user_")))
        atexit.register(shutil.rmtree, _WORK[0], True)
    return Path(tempfile.mkdtemp(dir=_WORK[0]))


def _fmu_archive(fmu: Path) -> Path:
    """A bare FMU as a one-component system (instance and model: its model identifier; the FMU's default
    experiment, else 1 s at 1 ms)."""
    import math

    from fmpy import read_model_description
    try:
        md = read_model_description(str(fmu))
    except Exception as err:                            # fmpy names the schema problem
        raise SystemDefinitionError(f"{fmu}: cannot read its modelDescription.xml: {err}") from None
    if md.coSimulation is None:
        raise SystemDefinitionError(f"{fmu}: a model-exchange-only FMU; ncfmu runs co-simulation FMUs only")
    ident = md.coSimulation.modelIdentifier
    exp = md.defaultExperiment
    stop = float(exp.stopTime) if exp is not None and exp.stopTime is not None else 1.0
    step = float(exp.stepSize) if exp is not None and getattr(exp, "stepSize", None) else min(1e-3, stop)
    if not (math.isfinite(stop) and stop > 0 and math.isfinite(step) and step > 0):
        stop, step = 1.0, 1e-3
    work = _workdir()
    system = System(fmu.stem, [Component(ident, ident)], [], stop, step, f"the FMU {fmu.name} alone")
    folder = write_system(system, work / "src")
    (work / "fmus").mkdir()
    shutil.copy(fmu, work / "fmus" / f"{ident}.fmu")
    return pack(folder, work / "fmus", work / f"{system.name}.ssp")


def _ssd_archive(ssd: Path) -> Path:
    """An .ssd and its folder (its resources/: the FMUs and .ssv files it names) packed as an .ssp."""
    import zipfile
    system = read_ssd(ssd)                          # every source checked: inside the folder
    folder = ssd.parent
    for comp in system.components:
        fmu_path(folder, comp)
    archive = _workdir() / f"{system.name}.ssp"
    base = folder.resolve()
    with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(ssd, SSD_NAME)
        for path in sorted((folder / "resources").rglob("*")) if (folder / "resources").is_dir() else []:
            resolved = path.resolve()
            if path.is_file() and base in resolved.parents:
                z.write(resolved, path.relative_to(folder).as_posix())
    return archive


def source_archive(source: str, root: Path | None = None) -> Path:
    """The .ssp a command runs for ``source``: a system's name, an .ssp, an .ssd (with its folder), an unpacked
    system folder (with ``SystemStructure.ssd``) or a bare .fmu."""
    p = Path(source)
    if p.suffix == ".fmu":
        if not p.is_file():
            raise SystemDefinitionError(f"FMU not found: {p}")
        return _fmu_archive(p)
    if p.suffix == ".ssd":
        if not p.is_file():
            raise SystemDefinitionError(f"SSD not found: {p}")
        return _ssd_archive(p)
    if p.is_dir():
        if not (p / SSD_NAME).is_file():
            raise SystemDefinitionError(f"{p}: a folder without {SSD_NAME}: not an unpacked system")
        return _ssd_archive(p / SSD_NAME)
    if p.suffix != ".ssp" and source not in SYSTEMS:
        raise SystemDefinitionError(f"unknown system {source!r}; known systems: {', '.join(SYSTEMS)} (or give an "
                                    ".ssp, an .ssd, an unpacked system folder or an .fmu)")
    return system_archive(source, root)


def _parse_pairs(items: Sequence[str], option: str, example: str) -> list[tuple[str, str]]:
    pairs = []
    for item in items:
        left, eq, right = item.partition("=")
        if not eq or not left or not right:
            raise SystemDefinitionError(f"{option} {item!r}: expected {example}")
        pairs.append((left.strip(), right.strip()))
    return pairs


def replaced(archive: Path, replace: Sequence[str], mapping: Sequence[str] = ()) -> tuple[Path, list[str]]:
    """``archive`` with components replaced by other FMUs: ``INSTANCE=PATH.fmu`` each, connections kept by variable
    name (``mapping``: ``INSTANCE.THEIRS=OURS``, the new FMU's name for an old connector). A connection to a variable
    the new FMU does not have is refused, naming it; the old parameter bindings apply where the new FMU has the
    variable (converted to its unit), the rest are named in a warning line. Returns the new archive and the
    warning lines."""
    from fmpy import read_model_description

    from .cosim.fmu import FMI3_TYPES
    from .cosim.units import conversion, unit_from_fmpy, variable_unit
    system = read_ssp(archive)
    work = _workdir()
    folder = safe_extract(archive, work / "old")
    renames: dict[str, dict[str, str]] = {}
    for left, theirs in _parse_pairs(mapping, "--map", "INSTANCE.THEIRS=OURS, e.g. --map x_axis.x=pos"):
        inst, dot, name = left.partition(".")
        if not dot:
            raise SystemDefinitionError(f"--map {left}={theirs}: expected INSTANCE.THEIRS=OURS")
        renames.setdefault(inst, {})[theirs] = name      # ours -> theirs
    replacing = _parse_pairs(replace, "--replace", "INSTANCE=PATH.fmu, e.g. --replace x_axis=my_axis.fmu")
    for inst in renames:
        if inst not in {i for i, _ in replacing}:
            raise SystemDefinitionError(f"--map {inst}.…: {inst} is not replaced (give --replace {inst}=PATH.fmu)")
    warnings: list[str] = []
    for inst, path in replacing:
        comp = system.component(inst)                    # names the instances when there is no such one
        fmu = Path(path)
        if not fmu.is_file() or fmu.suffix != ".fmu":
            raise SystemDefinitionError(f"--replace {inst}={path}: no such FMU file")
        try:
            new_md = read_model_description(str(fmu))
            old_md = read_model_description(str(fmu_path(folder, comp)))
        except Exception as err:
            raise SystemDefinitionError(f"--replace {inst}={path}: cannot read a modelDescription.xml: {err}") from None
        new = {v.name: v for v in new_md.modelVariables}
        old = {v.name: v for v in old_md.modelVariables}
        rename = renames.get(inst, {})
        for ours, theirs in rename.items():
            if theirs not in new:
                raise SystemDefinitionError(f"--map {inst}.{theirs}={ours}: {new_md.modelName} has no variable "
                                            f"{theirs!r}")
        used: dict[str, Any] = {}
        for c in system.connections:
            for end in ("start", "end"):
                if getattr(c, f"{end}_element") != inst:
                    continue
                ours = getattr(c, f"{end}_connector")
                theirs = rename.get(ours, ours)
                if theirs not in new:
                    raise SystemDefinitionError(f"--replace {inst}={path}: the connection {c} needs {inst}.{ours}, "
                                                f"which {new_md.modelName} does not have (map it: --map "
                                                f"{inst}.THEIRS={ours})")
                setattr(c, f"{end}_connector", theirs)
                used[theirs] = new[theirs]
        applied: dict[str, object] = {}
        dropped = []
        for name, value in comp.parameters.items():
            theirs = rename.get(name, name)
            v = new.get(theirs)
            if v is None or v.causality not in ("parameter", "input"):
                dropped.append(name)
                continue
            was, now = variable_unit(old[name]) if name in old else None, variable_unit(v)
            if was and now and was != now and isinstance(value, float):
                conv = conversion(unit_from_fmpy(was, old_md.unitDefinitions),
                                  unit_from_fmpy(now, new_md.unitDefinitions))
                if conv is not None:
                    value = conv.gain * value + conv.offset
            applied[theirs] = value
        if dropped:
            warnings.append(f"--replace {inst}: parameters not applied ({new_md.modelName} has no such variable): "
                            f"{', '.join(dropped)}")
        comp.parameters = applied
        comp.connectors = []
        for name, v in used.items():
            unit = variable_unit(v)
            comp.connectors.append((name, str(v.causality), FMI3_TYPES.get(v.type, v.type), unit))
            if unit and unit not in system.units:
                system.units[unit] = unit_from_fmpy(unit, new_md.unitDefinitions)
        others = {c.model for c in system.components if c is not comp}
        comp.model = fmu.stem if fmu.stem not in others else f"{inst}_{fmu.stem}"
        shutil.copy(fmu, folder / "resources" / f"{comp.model}.fmu")
    out = write_system(system, work / "src")
    return pack(out, folder / "resources", work / f"{system.name}.ssp"), warnings


def prepared_archive(source: str, replace: Sequence[str] = (), mapping: Sequence[str] = (),
                     root: Path | None = None) -> tuple[Path, list[str]]:
    """The .ssp a command runs: :func:`source_archive` of ``source``, with ``replace``/``mapping`` applied
    (:func:`replaced`); and the warning lines of the replacement."""
    archive = source_archive(source, root)
    if not replace:
        if mapping:
            raise SystemDefinitionError("--map needs --replace INSTANCE=PATH.fmu")
        return archive, []
    return replaced(archive, replace, mapping)
