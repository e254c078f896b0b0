"""An FMU's own documentation, generated from the artefacts themselves: ``documentation/index.html`` inside
every FMU (the FMI convention) and ``docs/fmus/<Model>.md`` -- behaviour (the controller's module documentation),
seed, and the interface table read from the FMU's own modelDescription."""

from __future__ import annotations

import ast
import html
import re
import sys
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path


def _variables(md_xml: bytes) -> list[dict[str, str]]:
    root = ET.fromstring(md_xml)
    rows = []
    variables = root.find("ModelVariables")
    assert variables is not None, "a modelDescription has ModelVariables"
    for sv in variables:
        typed = sv[0]
        rows.append({"name": sv.get("name", ""), "causality": sv.get("causality", ""), "type": typed.tag,
                     "unit": typed.get("unit", ""), "start": typed.get("start", ""),
                     "range": " .. ".join(x for x in (typed.get("min", ""), typed.get("max", "")) if x) if
                     (typed.get("min") or typed.get("max")) else "",
                     "description": sv.get("description", "")})
    return rows


def seed_text(logic) -> str:
    """The seed a model follows (its file among the seeds), or that it has none."""
    return logic.SEED or "none: ncfmu's own design"


def _module_doc(module) -> str | None:
    """A module's docstring; of a module compiled with mypyc, its source's (mypyc 2.4 gives a compiled module
    the docstring "mypyc filler docstring"; the FMU ships the source beside the extension)."""
    file = getattr(module, "__file__", None) or ""
    if file.endswith(".py"):
        return module.__doc__
    source = Path(file).parent / f"{module.__name__.rpartition('.')[2]}.py"
    return ast.get_docstring(ast.parse(source.read_text()), clean=False) if source.is_file() else module.__doc__


def _behaviour(logic) -> str:
    return (_module_doc(sys.modules[logic.__module__]) or logic.__doc__ or "").strip()


#: reStructuredText in the docstrings: a Sphinx role (``:func:`~ncfmu.servo.model.servo_axis```) or literal
#: (````program````); an FMU's documentation shows them as code, never as markup.
_ROLE = re.compile(r":(?P<role>[a-z]+):`(?P<target>[^`]+)`|``(?P<literal>[^`]+)``")


def _rendered(text: str, plain: Callable[[str], str], code: Callable[[str], str]) -> str:
    """``text`` with every role and literal given to ``code`` -- a role's target as its dotted name (a function
    or method with ``()``), a literal as it is -- and everything else to ``plain``."""
    out, at = [], 0
    for m in _ROLE.finditer(text):
        out.append(plain(text[at:m.start()]))
        name = m["literal"] if m["literal"] is not None else (
            m["target"].lstrip("~.") + ("()" if m["role"] in ("func", "meth") else ""))
        out.append(code(name))
        at = m.end()
    out.append(plain(text[at:]))
    return "".join(out)


def behaviour_html(logic) -> str:
    """The behaviour for an HTML ``<pre>``: escaped, names and literals as ``<code>``."""
    return _rendered(_behaviour(logic), html.escape, lambda name: f"<code>{html.escape(name)}</code>")


def behaviour_text(logic) -> str:
    """The behaviour as plain text (a Markdown text block): names and literals in single backquotes."""
    return _rendered(_behaviour(logic), lambda piece: piece, lambda name: f"`{name}`")


def _compact(rows: list[dict[str, str]]) -> list[dict[str, str]]:
    """Fold indexed ports (block[1..8].Xd) into one row each, so the table stays readable."""
    out: list[dict[str, str]] = []
    seen: dict[str, dict[str, str]] = {}
    for r in rows:
        name = r["name"]
        if "[" in name:
            head, rest = name.split("[", 1)
            index, tail = rest.split("]", 1)
            key = f"{head}[k]{tail}"
            if key in seen:
                seen[key]["_last"] = index
                continue
            r = dict(r, name=key, _first=index, _last=index,
                     description=r["description"].replace(f" {index}:", " k:"))
            seen[key] = r
        out.append(r)
    for r in out:
        if "_first" in r:
            r["name"] = r["name"].replace("[k]", f"[k], k = {r['_first']}..{r['_last']}")
            r["start"] = f"{r['start']} (k = {r['_first']})"
    return out


def fmu_html(md_xml: bytes, logic, built_with: str = "pythonfmu", extra: str = "") -> bytes:
    """The FMU's ``documentation/index.html``; ``extra`` is HTML appended (runtime needs, design figures)."""
    root = ET.fromstring(md_xml)
    rows = _compact(_variables(md_xml))
    table = "\n".join(
        "<tr>" + "".join(f"<td>{html.escape(str(r[c]))}</td>" for c in ("name", "causality", "type", "unit",
                                                                       "start", "range", "description")) + "</tr>"
        for r in rows)
    exp, cosim = root.find("DefaultExperiment"), root.find("CoSimulation")
    assert exp is not None and cosim is not None, "every modelDescription modeldesc.model_description writes has both"
    version = html.escape(root.get("version", ""))
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{logic.MODEL_NAME}</title>
<style>body{{font-family:sans-serif;max-width:60em;margin:2em auto}}td,th{{border-bottom:1px solid #ddd;
padding:2px 6px;text-align:left;vertical-align:top}}table{{border-collapse:collapse}}pre{{white-space:pre-wrap}}</style>
</head><body>
<h1>{logic.MODEL_NAME}</h1>
<p>{html.escape(logic.DESCRIPTION)}</p>
<p>Seed: <code>{html.escape(seed_text(logic))}</code>. Built by ncfmu {version} with {html.escape(built_with)}.
Default experiment: step {exp.get("stepSize")} s, stop {exp.get("stopTime")} s.
Capabilities: canGetAndSetFMUstate = {cosim.get("canGetAndSetFMUstate")}.</p>
<h2>Behaviour</h2>
<pre>{behaviour_html(logic)}</pre>
<h2>Interface</h2>
<table><tr><th>name</th><th>causality</th><th>type</th><th>unit</th><th>start</th><th>range</th><th>description</th></tr>
{table}
</table>
<p>Bad parameters are refused at fmi2ExitInitializationMode with a log message naming the variable, the value
and the rule.</p>
{extra}
</body></html>
"""
    return page.encode()


def fmu_markdown(md_xml: bytes, logic) -> str:
    rows = _compact(_variables(md_xml))
    lines = [f"# {logic.MODEL_NAME}", "", logic.DESCRIPTION, "", f"Seed: `{seed_text(logic)}`", "", "## Behaviour", "",
             "```text", behaviour_text(logic), "```", "", "## Interface", "",
             "| name | causality | type | unit | start | range | description |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append("| " + " | ".join(str(r[c]).replace("|", "\\|") for c in
                                         ("name", "causality", "type", "unit", "start", "range", "description")) + " |")
    return "\n".join(lines) + "\n"
