"""SSP 1.0 systems: write (.ssd / .ssv, flat, literal ``ssd:``/``ssc:``/``ssv:`` prefixes), read, pack.

Layout of a system source folder and of the packed archive (what libcosim and fmpy expect)::

    SystemStructure.ssd
    resources/<Model>.fmu            (archive only: added by ``pack``)
    resources/<instance>.ssv         one parameter set per component, plain variable names

Each component binds its own .ssv (``ssd:ParameterBinding source=...``): libcosim applies a
binding's parameters by plain name and ignores ``prefix``, so one set per component is what both
tools read the same way. Every .ssv carries the same set name, :data:`PARAMETER_SET`.
"""

from __future__ import annotations

import io
import math
import posixpath
import stat
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import SystemDefinitionError
from ..files import write_if_changed
from ..ports import NUMBER_RULE, UNITS, parse_real, parse_text
from .units import BASE, Unit

#: The most an archive may unpack to (its FMUs are a few MB): more is a zip bomb, not a system.
MAX_UNPACKED = 2 ** 30

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)

SSD_NAME = "SystemStructure.ssd"

#: The ``name`` of every .ssv parameter set, in every system. ecos applies parameter sets only when
#: asked by name (``ecos simulate ... --parameterSet parameters``) and merges the sets of that name
#: across components, so one shared name applies a whole system; one constant (not the system's
#: name) keeps that command the same for every system. libcosim applies each component's first
#: set whatever its name, and fmpy and ncfmu's reader ignore the name.
PARAMETER_SET = "parameters"


def _q(tag: str) -> str:
    prefix, local = tag.split(":")
    return f"{{{NS[prefix]}}}{local}"


@dataclass
class Component:
    """One FMU instance of a system."""

    name: str
    model: str                                   # FMU model name; source resources/<model>.fmu
    parameters: dict[str, object] = field(default_factory=dict)
    connectors: list[tuple[str, str, str, str | None]] = field(default_factory=list)  # name, kind, type, unit

    @property
    def source(self) -> str:
        return f"resources/{self.model}.fmu"


@dataclass
class Connection:
    start_element: str
    start_connector: str
    end_element: str
    end_connector: str

    def __str__(self) -> str:
        return f"{self.start_element}.{self.start_connector} -> {self.end_element}.{self.end_connector}"


@dataclass
class System:
    """A system: components in stepping order (Gauss-Seidel), connections, default experiment."""

    name: str
    components: list[Component]
    connections: list[Connection]
    stop_time: float
    step_size: float = 1e-3
    description: str = ""
    units: dict[str, Unit] = field(default_factory=dict)     # the SSD's unit definitions, by name

    def component(self, name: str) -> Component:
        for c in self.components:
            if c.name == name:
                return c
        raise SystemDefinitionError(f"system {self.name} has no instance {name!r} "
                                    f"(instances: {', '.join(c.name for c in self.components)})")


# -- writing --------------------------------------------------------------------------------------
def _value_element(parent: ET.Element, ns: str, value: object) -> None:
    if isinstance(value, bool):
        ET.SubElement(parent, _q(f"{ns}:Boolean"), value="true" if value else "false")
    elif isinstance(value, int):
        ET.SubElement(parent, _q(f"{ns}:Integer"), value=str(value))
    elif isinstance(value, float):
        ET.SubElement(parent, _q(f"{ns}:Real"), value=repr(value))
    else:
        ET.SubElement(parent, _q(f"{ns}:String"), value=str(value))


def ssv_document(parameters: dict[str, object], name: str = PARAMETER_SET) -> bytes:
    """One .ssv parameter set: plain variable names, typed values."""
    root = ET.Element(_q("ssv:ParameterSet"), version="1.0", name=name)
    params = ET.SubElement(root, _q("ssv:Parameters"))
    for pname, value in parameters.items():
        p = ET.SubElement(params, _q("ssv:Parameter"), name=pname)
        _value_element(p, "ssv", value)
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _unit_spec(name: str, defined: dict[str, Unit]) -> dict | None:
    """A unit's ``BaseUnit`` attributes: ncfmu's own units (ports.UNITS), else the system's definition."""
    if name in UNITS:
        return dict(UNITS[name])
    u = defined.get(name)
    if u is None or u.exponents is None:
        return None
    spec: dict[str, object] = {b: e for b, e in zip(BASE, u.exponents) if e}
    if u.factor != 1.0:
        spec["factor"] = u.factor
    if u.offset != 0.0:
        spec["offset"] = u.offset
    return spec


def ssd_document(system: System) -> bytes:
    root = ET.Element(_q("ssd:SystemStructureDescription"), version="1.0", name=system.name)
    sys_el = ET.SubElement(root, _q("ssd:System"), name=system.name, description=system.description)
    elements = ET.SubElement(sys_el, _q("ssd:Elements"))
    units = set()
    # Inputs are declared only where a connection drives them: fmpy's simulate_ssp cannot load an
    # SSD that declares an unconnected input; the FMU variable itself stays settable in every tool.
    driven = {(k.end_element, k.end_connector) for k in system.connections}
    for comp in system.components:
        c = ET.SubElement(elements, _q("ssd:Component"), name=comp.name,
                          type="application/x-fmu-sharedlibrary", source=comp.source)
        declared = [con for con in comp.connectors if con[1] != "input" or (comp.name, con[0]) in driven]
        if declared:
            cons = ET.SubElement(c, _q("ssd:Connectors"))
            for name, kind, typ, unit in declared:
                con = ET.SubElement(cons, _q("ssd:Connector"), name=name, kind=kind)
                t = ET.SubElement(con, _q(f"ssc:{typ}"))
                if unit:
                    t.set("unit", unit)
                    units.add(unit)
        if comp.parameters:
            bindings = ET.SubElement(c, _q("ssd:ParameterBindings"))
            ET.SubElement(bindings, _q("ssd:ParameterBinding"), source=f"resources/{comp.name}.ssv")
    cons = ET.SubElement(sys_el, _q("ssd:Connections"))
    for k in system.connections:
        ET.SubElement(cons, _q("ssd:Connection"), startElement=k.start_element, startConnector=k.start_connector,
                      endElement=k.end_element, endConnector=k.end_connector)
    if units:
        units_el = ET.SubElement(root, _q("ssd:Units"))
        for name in sorted(units):
            spec = _unit_spec(name, system.units)
            if spec is None:              # a unit known by its name only: referenced, not defined
                continue
            u = ET.SubElement(units_el, _q("ssc:Unit"), name=name)
            base = {k: str(v) for k, v in spec.items() if k not in ("factor", "offset")}
            for key in ("factor", "offset"):
                if key in spec:
                    base[key] = repr(spec[key])
            ET.SubElement(u, _q("ssc:BaseUnit"), base)
    exp = ET.SubElement(root, _q("ssd:DefaultExperiment"), startTime="0.0", stopTime=repr(float(system.stop_time)))
    ann = ET.SubElement(ET.SubElement(exp, _q("ssd:Annotations")), _q("ssc:Annotation"),
                        type="com.opensimulationplatform")
    algo = ET.SubElement(ann, _q("osp:Algorithm"))
    ET.SubElement(algo, _q("osp:FixedStepAlgorithm"), baseStepSize=repr(float(system.step_size)))
    ET.indent(root)
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def write_system(system: System, folder: Path) -> Path:
    """Write ``folder/<system>/SystemStructure.ssd`` and its .ssv files; return the system folder."""
    out = Path(folder) / system.name
    (out / "resources").mkdir(parents=True, exist_ok=True)
    write_if_changed(out / SSD_NAME, ssd_document(system))
    wanted = {f"{comp.name}.ssv": ssv_document(comp.parameters) for comp in system.components if comp.parameters}
    for old in (out / "resources").glob("*.ssv"):
        if old.name not in wanted:
            old.unlink()
    for name, data in wanted.items():
        write_if_changed(out / "resources" / name, data)
    return out


def pack(system_folder: Path, fmus_dir: Path, archive: Path) -> Path:
    """Pack a system folder and the FMUs it uses into an .ssp archive."""
    system_folder, archive = Path(system_folder), Path(archive)
    system = read_ssd(system_folder / SSD_NAME)
    packed = io.BytesIO()
    with zipfile.ZipFile(packed, "w", zipfile.ZIP_DEFLATED) as z:
        z.write(system_folder / SSD_NAME, SSD_NAME)
        for ssv in sorted((system_folder / "resources").glob("*.ssv")):
            z.write(ssv, f"resources/{ssv.name}")
        for model in sorted({c.model for c in system.components}):
            fmu = Path(fmus_dir) / f"{model}.fmu"
            if not fmu.is_file():
                raise SystemDefinitionError(f"{system.name}: FMU {fmu} is missing (run 'ncfmu build')")
            z.write(fmu, f"resources/{model}.fmu", compress_type=zipfile.ZIP_STORED)
    # entries carry their files' timestamps: unchanged inputs give the same bytes, and the archive stays as it is
    write_if_changed(archive, packed.getvalue())
    return archive


# -- reading --------------------------------------------------------------------------------------
def _parse_value(el: ET.Element, where: str) -> object:
    tag = el.tag.split("}")[-1]
    raw = el.get("value")
    if raw is None:
        raise SystemDefinitionError(f"{where}: {tag} has no value")
    try:
        return parse_text(tag, raw)
    except ValueError:
        rule = "" if raw.isascii() else f" ({NUMBER_RULE})"
        raise SystemDefinitionError(f"{where}: {raw!r} is not a valid {tag}{rule}") from None


def _attribute(element: ET.Element, name: str, where: object) -> str:
    """An attribute the element cannot do without."""
    value = element.get(name)
    if value is None:
        raise SystemDefinitionError(f"{where}: {element.tag.split('}')[-1]} without a {name} attribute")
    return value


def _parameter_set(root: ET.Element, where: str) -> dict[str, object]:
    values = {}
    for p in root.iter(_q("ssv:Parameter")):
        typed = [child for child in p if child.tag.startswith("{" + NS["ssv"])]
        if not typed:
            raise SystemDefinitionError(f"{where}: parameter {p.get('name')!r} has no value element")
        values[_attribute(p, "name", where)] = _parse_value(typed[0], f"{where}: parameter {p.get('name')}")
    return values


def _time_attribute(path: Path, element: ET.Element, name: str) -> float:
    raw = element.get(name)
    try:
        value = parse_real(raw if raw is not None else "")     # a missing attribute is refused as an empty one
    except ValueError:
        raise SystemDefinitionError(f"{path}: {name}={raw!r}: must be a time in seconds") from None
    if not math.isfinite(value) or value < 0:
        raise SystemDefinitionError(f"{path}: {name}={raw!r}: must be a finite time >= 0")
    return value


def _model_of(path: Path, name: str, source: str) -> str:
    """The model of a component whose ``source`` is ``resources/<Model>.fmu``, a file of the archive itself.

    Anything else could make a system load code from outside the archive (or its folder): ``..``, a folder,
    an absolute path, a drive, a URL of any scheme. All are refused, naming the component.
    """
    flat = source.startswith("resources/") and source.endswith(".fmu")
    model = source[len("resources/"):-len(".fmu")] if flat else ""
    if not model or model in (".", "..") or any(ch in model for ch in "/\\:\0"):
        raise SystemDefinitionError(f"{path}: component {name}: source {source!r}: an FMU is loaded only from inside "
                                    "the archive, as resources/<Model>.fmu (no '..', folders, absolute paths or "
                                    "URLs)")
    return model


def is_link(entry: zipfile.ZipInfo) -> bool:
    """Whether an archive entry is a symbolic link (unix mode bits in the entry's external attributes)."""
    return stat.S_ISLNK(entry.external_attr >> 16)


def fmu_path(folder: Path, component: Component, origin: Path | None = None) -> Path:
    """The FMU file of ``component`` in the system unpacked in ``folder`` (an extracted archive or the folder of
    an .ssd): inside that folder, or refused -- a symbolic link may point elsewhere in the folder, not out of it.
    Errors name ``origin`` (the archive ``folder`` was extracted from), else ``folder``."""
    base = Path(folder).resolve()
    where = origin if origin is not None else folder
    target = (base / component.source).resolve()
    if base not in target.parents:
        raise SystemDefinitionError(f"{where}: component {component.name}: {component.source} leads outside the "
                                    f"system folder (to {target}): an FMU is loaded only from inside it")
    if not target.is_file():
        raise SystemDefinitionError(f"{where}: component {component.name}: FMU not found: {component.source}")
    return target


def read_ssd(path: Path, read_file=None) -> System:
    """Read a system from an .ssd file (or, with ``read_file``, from inside an archive).

    ``read_file(relative_path) -> bytes`` reads files the .ssd refers to; by default they are read
    next to the .ssd on disk.
    """
    path = Path(path)
    if read_file is None:
        base = path.parent

        def read_file(rel: str) -> bytes:
            target = (base / rel).resolve()
            if base.resolve() not in target.parents:
                raise SystemDefinitionError(f"{path}: {rel!r} points outside the system folder")
            if not target.is_file():
                raise SystemDefinitionError(f"{path}: parameter file {rel!r} is missing")
            return target.read_bytes()
        text = path.read_bytes()
    else:
        text = read_file(SSD_NAME)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as err:
        raise SystemDefinitionError(f"{path}: not well-formed XML: {err}") from None
    if root.tag != _q("ssd:SystemStructureDescription"):
        raise SystemDefinitionError(f"{path}: root element is {root.tag}, expected ssd:SystemStructureDescription")
    sys_el = root.find(_q("ssd:System"))
    elements = sys_el.find(_q("ssd:Elements")) if sys_el is not None else None
    if sys_el is None or elements is None:
        raise SystemDefinitionError(f"{path}: no ssd:System with ssd:Elements (the components) in it")
    components = []
    names: set[str] = set()
    for comp in elements.findall(_q("ssd:Component")):
        name = _attribute(comp, "name", path)
        if name in names:
            raise SystemDefinitionError(f"{path}: component name {name!r} is used twice: every component needs a "
                                        "name of its own")
        names.add(name)
        model = _model_of(path, name, comp.get("source", ""))
        connectors: list[tuple[str, str, str, str | None]] = []
        for con in comp.iterfind(f"{_q('ssd:Connectors')}/{_q('ssd:Connector')}"):
            typed = list(con)
            typ = typed[0].tag.split("}")[-1] if typed else "Real"
            where = f"{path}: component {name}"
            connectors.append((_attribute(con, "name", where), _attribute(con, "kind", where), typ,
                               typed[0].get("unit") if typed else None))
        params: dict[str, object] = {}
        for binding in comp.iterfind(f"{_q('ssd:ParameterBindings')}/{_q('ssd:ParameterBinding')}"):
            prefix = binding.get("prefix", "")
            src = binding.get("source")
            if src:
                where = f"{path}: {src}"
                try:
                    values = _parameter_set(ET.fromstring(read_file(src)), where)
                except ET.ParseError as err:
                    raise SystemDefinitionError(f"{where}: not well-formed XML: {err}") from None
            else:
                values = _parameter_set(binding, f"{path}: component {name}")
            for k, v in values.items():
                params[k[len(prefix):] if prefix and k.startswith(prefix) else k] = v
        components.append(Component(name, model, params, connectors))
    connections = [Connection(_attribute(c, "startElement", path), _attribute(c, "startConnector", path),
                              _attribute(c, "endElement", path), _attribute(c, "endConnector", path))
                   for c in sys_el.iterfind(f"{_q('ssd:Connections')}/{_q('ssd:Connection')}")]
    units: dict[str, Unit] = {}
    for u in root.iterfind(f"{_q('ssd:Units')}/{_q('ssc:Unit')}"):
        name = _attribute(u, "name", path)
        base_unit = u.find(_q("ssc:BaseUnit"))
        attrs = dict(base_unit.attrib) if base_unit is not None else {}
        units[name] = Unit.of(name, attrs, attrs.get("factor", 1.0), attrs.get("offset", 0.0))
    exp = root.find(_q("ssd:DefaultExperiment"))
    stop = _time_attribute(path, exp, "stopTime") if exp is not None and exp.get("stopTime") else math.nan
    step = 1e-3
    fixed = root.find(f".//{_q('osp:FixedStepAlgorithm')}")
    if fixed is not None:
        step = _time_attribute(path, fixed, "baseStepSize")
        if not step > 0:
            raise SystemDefinitionError(f"{path}: baseStepSize = {step!r}: must be > 0")
    return System(_attribute(root, "name", path), components, connections, stop, step,
                  sys_el.get("description", ""), units)


def read_ssp(archive: Path) -> System:
    """Read the system of an .ssp archive (without extracting it)."""
    archive = Path(archive)
    if not archive.is_file():
        raise SystemDefinitionError(f"SSP archive not found: {archive}")
    try:
        z = zipfile.ZipFile(archive)
    except (zipfile.BadZipFile, OSError) as err:
        raise SystemDefinitionError(f"{archive}: not an SSP archive (a zip file): {err}") from None
    with z:
        names = set(z.namelist())
        # before anything is read: a few MB can unpack to GBs (one entry of spaces is enough)
        total = sum(info.file_size for info in z.infolist())
        if total > MAX_UNPACKED:
            raise SystemDefinitionError(f"{archive}: unpacks to more than {MAX_UNPACKED / 2 ** 30:g} GiB "
                                        f"({total / 2 ** 30:.1f} GiB): refused")

        def read_file(rel: str) -> bytes:
            # SSP sources are relative URIs: "./resources/x.ssv" names the entry "resources/x.ssv"
            entry = posixpath.normpath(rel)
            if entry == ".." or entry.startswith(("../", "/")) or entry not in names:
                raise SystemDefinitionError(f"{archive}: {rel!r} is not in the archive")
            return z.read(entry)
        system = read_ssd(archive, read_file)
        for comp in system.components:
            if comp.source in names and is_link(z.getinfo(comp.source)):
                target = z.read(comp.source).decode(errors="replace")
                raise SystemDefinitionError(f"{archive}: component {comp.name}: {comp.source} is a symbolic link in "
                                            f"the archive (to {target!r}): an FMU is loaded only from inside the "
                                            "archive")
        return system
