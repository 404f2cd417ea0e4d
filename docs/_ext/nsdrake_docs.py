"""Sphinx directives that render nsdrake's reference from the code itself, so it cannot drift.

- ``pydrake_system``: the port block pydrake's own docstrings use (Drake renders it with
  its own extension, which pydrake does not ship): inputs → system → outputs.
- ``nsdrake-ports``: a System's port table (name, size, unit, meaning) read from its
  docstring's ``Inputs:`` / ``Outputs:`` prose; with ``:build:`` the ports of a system
  built by that function must be exactly the documented ones, or the build warns (an
  error under ``sphinx-build -W``).
- ``nsdrake-fields``: a typed dataclass tree (a scenario, ControllerConfig) as tables,
  one per dataclass: dotted field path, type, default, unit and the field's own comment
  in the source (``# meaning [unit]`` above the field). A field without a comment warns.

Autodoc documentation of a dataclass gets its field table appended (``autodoc-process-
docstring``), from the same parser.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import inspect
import io
import re
import textwrap
import tokenize
import typing

import yaml
from docutils import nodes
from docutils.parsers.rst import directives
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)


def import_object(path: str):
    """``package.module.Name`` (or ``package.module:function``) → the object."""
    module, _, name = path.replace(":", ".").rpartition(".")
    return getattr(importlib.import_module(module), name)


# --- dataclass fields and their comments ---------------------------------------------------

UNIT = re.compile(r"\s*\[([^\[\]]*)\]\.?\s*$")
LEADING_UNIT = re.compile(r"^\[([^\[\]]*)\]\s*")


@dataclasses.dataclass
class FieldDoc:
    name: str
    type: str
    default: str
    unit: str
    meaning: str
    nested: type | None  # the dataclass of a section (or of a list's items)


def trailing_comments(source: str) -> dict[int, str]:
    """Line number → the comment that ends that line of code."""
    comments, code_lines = {}, set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type == tokenize.COMMENT:
            comments[token.start[0]] = token.string.lstrip("#").strip()
        elif token.type not in (tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT):
            code_lines.add(token.start[0])
    return {row: text for row, text in comments.items() if row in code_lines}


def field_comments(cls) -> dict[str, str]:
    """Each field's comment: the ``#`` lines directly above it in the class body, else the
    comment at the end of its line; a field on the line right after a commented field
    shares that comment (``camera_position`` / ``camera_target``)."""
    source = textwrap.dedent(inspect.getsource(cls))
    lines = source.splitlines()
    trailing = trailing_comments(source)
    (class_def,) = ast.parse(source).body
    comments, previous = {}, None
    for statement in class_def.body:
        if not isinstance(statement, ast.AnnAssign) or not isinstance(statement.target, ast.Name):
            previous = None
            continue
        row = statement.lineno - 2  # 0-based index of the line above
        block = []
        while row >= 0 and lines[row].strip().startswith("#"):
            block.insert(0, lines[row].strip().lstrip("#").strip())
            row -= 1
        name = statement.target.id
        if block:
            comments[name] = " ".join(block)
        elif statement.end_lineno in trailing:
            comments[name] = trailing[statement.end_lineno]
        elif (
            previous is not None
            and previous[1] == statement.lineno - 1
            and ast.dump(previous[2]) == ast.dump(statement.annotation)
        ):
            comments[name] = comments.get(previous[0], "")
        previous = (name, statement.end_lineno, statement.annotation)
    return comments


def type_name(annotation) -> str:
    if isinstance(annotation, type) and not typing.get_args(annotation):
        return annotation.__name__
    text = str(annotation).replace("typing.", "")
    return re.sub(r"\b(?:[a-z_]+\.)+([A-Za-z_]+)", r"\1", text)


def item_dataclass(annotation) -> type | None:
    if dataclasses.is_dataclass(annotation):
        return annotation
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) is list and args and dataclasses.is_dataclass(args[0]):
        return args[0]
    return None


def field_docs(cls) -> list[FieldDoc]:
    comments = field_comments(cls)
    hints = typing.get_type_hints(cls)
    docs = []
    for f in dataclasses.fields(cls):
        if f.name.startswith("_") or not f.init:
            continue
        annotation = hints[f.name]
        nested = item_dataclass(annotation)
        if f.default is not dataclasses.MISSING:
            default = repr(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            value = f.default_factory()
            default = "(section)" if dataclasses.is_dataclass(value) else repr(value)
        else:
            default = "(required)"
        comment = comments.get(f.name, "")
        unit = ""
        match = UNIT.search(comment) or LEADING_UNIT.match(comment)
        if match:
            unit, comment = match.group(1), (comment[: match.start()] + comment[match.end() :]).strip()
            unit = "" if unit == "-" else unit
        docs.append(FieldDoc(f.name, type_name(annotation), default, unit, comment, nested))
    return docs


SPHINX_ROLE = re.compile(r":(?:py:)?(?:mod|func|class|data|meth|attr|obj|exc):`~?([^`]+)`")


def inline(text: str) -> list[nodes.Node]:
    """Plain text with ``code`` and `code` spans as literals; a Python role of a docstring
    (:mod:`nsdrake.x`) is shown as its target, a literal (never the raw role)."""
    text = SPHINX_ROLE.sub(r"``\1``", text)
    parts = re.split(r"``([^`]+)``|`([^`]+)`", text)
    out = []
    for i, part in enumerate(parts):
        if part is None or part == "":
            continue
        out.append(nodes.literal(part, part) if i % 3 else nodes.Text(part))
    return out


def table(header: list[str], rows: list[list[list[nodes.Node]]], widths: list[int]) -> nodes.table:
    tbl = nodes.table(classes=["nsdrake-table"])
    group = nodes.tgroup(cols=len(header))
    tbl += group
    for width in widths:
        group += nodes.colspec(colwidth=width)
    head = nodes.thead()
    group += head
    row = nodes.row()
    for title in header:
        row += nodes.entry("", nodes.paragraph("", title))
    head += row
    body = nodes.tbody()
    group += body
    for cells in rows:
        row = nodes.row()
        for cell in cells:
            row += nodes.entry("", nodes.paragraph("", "", *cell))
        body += row
    return tbl


def fields_table(cls, prefix: str, location, warn: bool = True) -> nodes.table:
    rows = []
    for doc in field_docs(cls):
        path = f"{prefix}{doc.name}"
        meaning = doc.meaning
        if doc.nested is not None:
            kind = "list of" if doc.type.startswith("list") else "section"
            meaning = f"{meaning} " if meaning else ""
            meaning += f"({kind} {doc.nested.__name__}: below, {path})"
        elif not meaning and not doc.unit and warn:
            logger.warning(f"{cls.__module__}.{cls.__qualname__}.{doc.name}: no comment", location=location)
        rows.append(
            [
                [nodes.literal(path, path)],
                [nodes.literal(doc.type, doc.type)],
                [nodes.literal(doc.default, doc.default)] if doc.nested is None else [nodes.Text("")],
                [nodes.Text(doc.unit)],
                inline(meaning),
            ]
        )
    return table(["field", "type", "default", "unit", "meaning"], rows, [22, 12, 12, 10, 44])


def first_paragraph(cls) -> str:
    doc = cls.__doc__ or ""
    if doc.startswith(f"{cls.__name__}(") or not doc.strip():  # dataclass's generated signature
        return ""
    return " ".join(inspect.cleandoc(doc).split("\n\n")[0].split())


class FieldsDirective(SphinxDirective):
    """``.. nsdrake-fields:: package.module.Dataclass`` with ``:prefix:`` (the tree's dotted
    path, e.g. ``config.``) and ``:skip:`` (top-level fields left out, space-separated)."""

    required_arguments = 1
    option_spec = {"prefix": directives.unchanged, "skip": directives.unchanged}

    def run(self):
        root = import_object(self.arguments[0])
        skip = set(self.options.get("skip", "").split())
        out, seen = [], set()
        queue = [(root, self.options.get("prefix", ""))]
        while queue:
            cls, prefix = queue.pop(0)
            if (cls, prefix) in seen:
                continue
            seen.add((cls, prefix))
            title = prefix.rstrip(".") or cls.__name__
            section_id = nodes.make_id(f"fields-{self.arguments[0]}-{title}")
            rubric = nodes.rubric("", "", nodes.literal(title, title), nodes.Text(f"  ({cls.__name__})"))
            rubric["ids"].append(section_id)
            out.append(rubric)
            intro = first_paragraph(cls)
            if intro:
                out.append(nodes.paragraph("", "", *inline(intro)))
            tbl = fields_table(cls, prefix, self.get_location())
            if cls is root and skip:
                body = tbl.next_node(nodes.tbody)
                for row in list(body.children):
                    if row.astext().split(prefix, 1)[-1].split()[0] in skip:
                        body.remove(row)
            out.append(tbl)
            for doc in field_docs(cls):
                if doc.nested is not None and not (cls is root and doc.name in skip):
                    suffix = "[]." if doc.type.startswith("list") else "."
                    queue.append((doc.nested, f"{prefix}{doc.name}{suffix}"))
        return out


class FieldsTableDirective(SphinxDirective):
    """One dataclass's own fields (autodoc appends it to a dataclass's docstring)."""

    required_arguments = 1

    def run(self):
        return [fields_table(import_object(self.arguments[0]), "", self.get_location())]


def append_fields(app, what, name, obj, options, lines):
    if what == "class" and dataclasses.is_dataclass(obj) and obj.__module__.startswith("nsdrake"):
        lines.extend(["", f".. nsdrake-fields-table:: {obj.__module__}.{obj.__qualname__}", ""])


# --- ports --------------------------------------------------------------------------------


def port_block(doc: str) -> dict:
    """The ``.. pydrake_system::`` block of a docstring, as its YAML."""
    doc = inspect.cleandoc(doc)
    match = re.search(r"\.\. pydrake_system::\n\n((?:[ ]{4}.*\n|\n)+)", doc + "\n")
    if not match:
        raise ValueError("no '.. pydrake_system::' block")
    return yaml.safe_load(textwrap.dedent(match.group(1)))


def port_name(entry: str) -> str:
    return entry.split(" (")[0].strip()


ITEM = re.compile(r"^- ((?:``\w+``(?:, )?)+) \(([^()]*)\) \[([^\[\]]*)\]: (.*)$")


def port_rows(doc: str) -> dict[str, dict[str, tuple[str, str, str]]]:
    """The ``Inputs`` and ``Outputs`` lists of a docstring: ``in``/``out`` → port name →
    (size, unit, meaning), from items ``- ``name``, ``name`` (size) [unit]: meaning``.
    A unit list with one unit per name of the item is split among them."""
    doc = inspect.cleandoc(doc)
    rows: dict[str, dict[str, tuple[str, str, str]]] = {"in": {}, "out": {}}
    kind, item = None, None
    for line in doc.splitlines() + [""]:
        if re.match(r"^(Inputs|Outputs)\b.*:$", line):
            kind = "in" if line.startswith("Inputs") else "out"
            continue
        if kind is None:
            continue
        if line.startswith("- ") or not line.strip() or not line.startswith("  "):
            if item is not None:
                match = ITEM.match(" ".join(item.split()))
                if not match:
                    raise ValueError(f"a port item not in the form - ``name`` (size) [unit]: {item[:60]}")
                names = re.findall(r"``(\w+)``", match.group(1))
                size = match.group(2).removesuffix(" each")
                units = [u.strip() for u in match.group(3).split(",")]
                for k, name in enumerate(names):
                    unit = units[k] if len(names) > 1 and len(units) == len(names) else match.group(3)
                    rows[kind][name] = (size, "" if unit == "-" else unit, match.group(4))
                item = None
            if line.startswith("- "):
                item = line
            elif line.strip() and not line.startswith("  "):
                kind = None
        else:
            item += " " + line.strip()
    return rows


class PortsDirective(SphinxDirective):
    """``.. nsdrake-ports:: package.Class`` with ``:build: module:function`` (a System built
    by that function, whose ports must be exactly the documented ones)."""

    required_arguments = 1
    option_spec = {"build": directives.unchanged}

    def run(self):
        cls = import_object(self.arguments[0])
        block = port_block(cls.__doc__)
        inputs = [port_name(p) for p in block.get("input_ports", [])]
        outputs = [port_name(p) for p in block.get("output_ports", [])]
        described = port_rows(cls.__doc__)
        if "build" in self.options:
            system = import_object(self.options["build"])()
            built_in = {system.get_input_port(i).get_name() for i in range(system.num_input_ports())}
            built_out = {system.get_output_port(i).get_name() for i in range(system.num_output_ports())}
            for kind, documented, built in (("input", inputs, built_in), ("output", outputs, built_out)):
                if set(documented) != built:
                    logger.warning(
                        f"{self.arguments[0]}: documented {kind} ports {sorted(set(documented) - built)} "
                        f"not built, built {sorted(built - set(documented))} not documented",
                        location=self.get_location(),
                    )
        tables = []  # one table of inputs, one of outputs: the port name alone in its column
        for kind, names in (("in", inputs), ("out", outputs)):
            rows = []
            for name in names:
                if name not in described[kind]:
                    logger.warning(
                        f"{self.arguments[0]}: port {name} is not described", location=self.get_location()
                    )
                    continue
                size, unit, text = described[kind][name]
                meaning = inline(text)
                if name == "mode":  # every mode column links the page of Fig. 1's tree
                    link = nodes.reference("", "Fig. 1's decision tree", refuri="decision_tree.html")
                    meaning += [nodes.Text(" ("), link, nodes.Text(")")]
                rows.append([[nodes.literal(name, name)], [nodes.Text(size)], [nodes.Text(unit)], meaning])
            title = "input port" if kind == "in" else "output port"
            tables.append(
                table([title, "size", "unit", "meaning (the class's docstring)"], rows, [28, 8, 10, 54])
            )
        return tables


class PydrakeSystemDirective(SphinxDirective):
    """The port block of pydrake's docstrings, drawn as inputs → system → outputs."""

    has_content = True

    def run(self):
        spec = yaml.safe_load("\n".join(self.content))
        left = [[nodes.literal(p, p)] for p in spec.get("input_ports", [])]
        right = [[nodes.literal(p, p)] for p in spec.get("output_ports", [])]
        rows = []
        for k in range(max(len(left), len(right), 1)):
            name = spec.get("name", "") if k == 0 else ""
            rows.append(
                [
                    left[k] if k < len(left) else [nodes.Text("")],
                    [nodes.strong(name, name)] if name else [nodes.Text("")],
                    right[k] if k < len(right) else [nodes.Text("")],
                ]
            )
        return [table(["input ports", "system", "output ports"], rows, [40, 20, 40])]


# --- measured tables -----------------------------------------------------------------------


class ResultsDirective(SphinxDirective):
    """``.. nsdrake-results:: FAMILY``: the family's description (its file in
    nsdrake/studies/families/), the command that measures it, and its table: the
    ``table.md`` that command wrote, committed as docs/results/FAMILY/table.md. For a
    benchmark's table (no family file) the command is docs/results/FAMILY/command. The
    directive's content (the page's copy of the table, for readers of the source) is not
    rendered; a missing table.md is a warning (an error under ``sphinx-build -W``), never a
    placeholder on the site."""

    required_arguments = 1
    has_content = True

    def run(self):
        from pathlib import Path

        from docutils.statemachine import StringList

        family = self.arguments[0]
        docs = Path(self.env.srcdir)
        families = docs.parent / "nsdrake" / "studies" / "families"
        family_file = families / f"{family}.yaml"
        command_file = docs / "results" / family / "command"
        if not command_file.exists():  # a further table its parent's command wrote (drive/filter)
            command_file = command_file.parent.parent / "command"
        # a part of a family's table (null_space_laws/task): the table only, its family's
        # description and command are above its first part
        part = "/" in family and (families / f"{family.split('/')[0]}.yaml").exists()
        out = []
        if family_file.exists():  # a comparison family: its description, then its command
            spec = yaml.safe_load(family_file.read_text())
            out.append(nodes.paragraph("", "", *inline(" ".join(spec["description"].split()))))
            command = f"nsdrake compare {family}"
            out.append(nodes.literal_block(command, command, language="bash"))
        elif not part:  # a benchmark's table (bench/bench_FAMILY.py): the command it was measured with
            self.env.note_dependency(str(command_file))
            command = command_file.read_text().strip()
            out.append(nodes.literal_block(command, command, language="bash"))
        table_file = docs / "results" / family / "table.md"
        container = nodes.container(classes=["nsdrake-results"])
        if table_file.exists():
            self.env.note_dependency(str(table_file))
            text = table_file.read_text().splitlines()
            if text and text[0].startswith("# "):  # the file's title: the page's section has one
                text = text[1:]
            if family_file.exists() or part:  # the description is the family file's, shown above
                text = text[next((k for k, line in enumerate(text) if line.startswith("|")), len(text)) :]
            self.state.nested_parse(StringList(text, source=str(table_file)), 0, container)
        else:  # a page asks for a table nobody committed: an error under -W, no placeholder
            logger.warning(
                f"docs/results/{family}/table.md does not exist: run "
                f"'python scripts/regenerate_results.py --family {family}' and commit it",
                location=self.get_location(),
            )
        out.append(container)
        return out


# --- a figure in the prose, from its table -------------------------------------------------

FIGURE = re.compile(r"^(?P<written>.+?)\s*<(?P<target>[^<>]+)>$", re.S)
NUMBER = re.compile(r"^(?P<number>[−-]?\d+(?:[.,]\d+)?(?:e[−-]?\d+)?)(?:\s*(?P<unit>.*?))?$")
PREFIXES = {"": 1.0, "k": 1e3, "m": 1e-3, "µ": 1e-6, "n": 1e-9}
CELL_UNIT = re.compile(r"^[^\s:;,()]*(?: [^\s:;,()]+)?$")  # a unit: at most two words ('N m'), no punctuation
FIGURE_ROLE = re.compile(r"\{nsdrake-figure\}`([^`]+)`")


def results_table(root, name: str) -> tuple[list[str], list[list[str]]]:
    """docs/results/NAME/table.md: (its header's cells, its rows' cells)."""
    from pathlib import Path

    path = Path(root) / "docs" / "results" / name / "table.md"
    if not path.exists():
        raise ValueError(f"docs/results/{name}/table.md does not exist")
    lines = [line for line in path.read_text().splitlines() if line.startswith("|")]
    cells = [[c.strip() for c in line.strip().strip("|").split("|")] for line in lines]
    return cells[0], cells[2:]


def parse_number(text: str) -> tuple[float, int, str] | None:
    """'375 µs' → (375.0, 0 decimals, 'µs'); '2.3e-13' → (2.3e-13, 14 decimals, ''); None for text
    that is not a number (and unit)."""
    match = NUMBER.match(text.strip().replace("\u2009", "").replace("−", "-"))
    if not match:
        return None
    number = match.group("number").replace(",", ".")
    mantissa, _, exponent = number.lower().partition("e")
    # the decimals of the figure itself: '2.3e-13' is written to 14 decimals, not 1
    decimals = (len(mantissa.split(".")[1]) if "." in mantissa else 0) - int(exponent or 0)
    return float(number), decimals, (match.group("unit") or "").strip()


def figure_problem(root, written: str, target: str) -> str | None:
    """Why ``written`` is not the figure ``target`` names (None when it is). The target is
    ``RESULTS | ROW | COLUMN [| UNIT]``: the table docs/results/RESULTS/table.md, the one row
    whose first cell is ROW (else the one whose first cell contains it), the column headed
    COLUMN. The written figure is that
    cell rounded to the decimals written ('99.7%' for a cell '99.70%'); a cell that is a
    bare number needs UNIT, the cell's unit ('m'), and the written figure may carry a
    prefix of it ('62.9 µm'; '%' for a UNIT '1'); a cell of prose must contain the written
    text word for word. ROW may be ``ROW ÷ ROW2``: the written figure is then the ratio of
    the two rows' cells, a bare number ('2.2' for 'en_rms' of a row over the clean one's)."""
    parts = [p.strip() for p in target.split("|")]
    if len(parts) not in (3, 4):
        return f"'{target}': not RESULTS | ROW | COLUMN [| UNIT]"
    name, row_key, column, unit = (*parts, "")[:4]
    try:
        header, rows = results_table(root, name)
    except ValueError as error:
        return str(error)
    if column not in header:
        return f"docs/results/{name}/table.md has no column '{column}'"
    if "÷" in row_key:
        return ratio_problem(name, header, rows, written, row_key, column)
    row = find_row(name, rows, row_key)
    if isinstance(row, str):
        return row
    cell = row[header.index(column)]
    have, want = parse_number(cell), parse_number(written)
    if have is not None and not CELL_UNIT.match(have[2]):
        have = None  # a sentence that starts with a figure ('0.598 s: a link touched …') is prose
    if have is None or want is None:
        if re.search(rf"(?<![\w.]){re.escape(written)}(?![\w])", cell):
            return None
        return f"'{written}' is not in docs/results/{name}/table.md's '{column}' of '{row_key}': '{cell}'"
    value, _, cell_unit = have
    number, decimals, written_unit = want
    if cell_unit:
        scale = 1.0 if written_unit == cell_unit else None
    elif unit == "1" and written_unit == "%":
        scale = 0.01
    else:
        prefix = written_unit[: len(written_unit) - len(unit)] if written_unit.endswith(unit) else None
        scale = PREFIXES.get(prefix) if unit or not written_unit else None
    if scale is None:
        return f"'{written}': its unit is not the cell's ('{cell}', unit '{cell_unit or unit}')"
    if abs(value / scale - number) > 0.5 * 10.0**-decimals * (1 + 1e-9):
        return f"'{written}' is not '{cell}' (docs/results/{name}/table.md, '{row_key}', '{column}')"
    return None


def find_row(name: str, rows: list[list[str]], key: str) -> list[str] | str:
    """The one row whose first cell is ``key`` (else contains it), or why there is none."""
    found = [row for row in rows if row[0] == key] or [row for row in rows if key in row[0]]
    if len(found) != 1:
        return f"docs/results/{name}/table.md: {len(found)} rows contain '{key}' (one needed)"
    return found[0]


def ratio_problem(name, header, rows, written, row_key, column) -> str | None:
    """``ROW ÷ ROW2``: the written figure, a bare number, is ROW's cell over ROW2's in the
    column, rounded to the digits written (a ratio the prose states: '× 2.2')."""
    numerator, denominator = (find_row(name, rows, k.strip()) for k in row_key.split("÷", 1))
    for row in (numerator, denominator):
        if isinstance(row, str):
            return row
    column_index = header.index(column)
    top, bottom = (parse_number(r[column_index]) for r in (numerator, denominator))
    want = parse_number(written)
    if top is None or bottom is None or not bottom[0]:
        return f"docs/results/{name}/table.md: '{row_key}' in '{column}' is not a ratio of two numbers"
    if want is None or want[2]:
        return f"'{written}': a ratio is a bare number"
    ratio = top[0] / bottom[0]
    if abs(ratio - want[0]) > 0.5 * 10.0 ** -want[1] * (1 + 1e-9):
        return f"'{written}' is not {ratio:.4g} (docs/results/{name}/table.md, '{row_key}', '{column}')"
    return None


def figure_role(name, rawtext, text, lineno, inliner, options=None, content=None):
    """``{nsdrake-figure}`375 µs <drive | silence bound 200 | CPU p99.9>```: the figure as
    written, checked at build against the table it comes from (``figure_problem``); a
    figure that differs is a warning (an error under ``sphinx-build -W``)."""
    from pathlib import Path

    env = inliner.document.settings.env
    match = FIGURE.match(text)
    problem = "not 'FIGURE <RESULTS | ROW | COLUMN>'" if not match else None
    if match:
        root = Path(env.srcdir).parent
        problem = figure_problem(root, match.group("written"), match.group("target"))
        name_of = match.group("target").split("|")[0].strip()
        env.note_dependency(str(root / "docs" / "results" / name_of / "table.md"))
    if problem:
        logger.warning(f"nsdrake-figure: {problem}", location=(env.docname, lineno))
    written = match.group("written") if match else text
    return [nodes.inline(rawtext, written, classes=["nsdrake-figure"])], []


def setup(app):
    app.add_directive("pydrake_system", PydrakeSystemDirective)
    app.add_directive("nsdrake-ports", PortsDirective)
    app.add_directive("nsdrake-fields", FieldsDirective)
    app.add_directive("nsdrake-fields-table", FieldsTableDirective)
    app.add_directive("nsdrake-results", ResultsDirective)
    app.add_role("nsdrake-figure", figure_role)
    app.connect("autodoc-process-docstring", append_fields)
    return {"parallel_read_safe": True, "parallel_write_safe": True, "version": "1"}


def panda_pose_controller():
    """The controller on urdf/panda.urdf with the full pose task and a force axis: every
    port it can have (the rotational inputs exist only with rotational task axes)."""
    from pathlib import Path

    import nsdrake

    urdf = Path(__file__).resolve().parents[2] / "urdf" / "panda.urdf"
    return nsdrake.NullSpaceImpedanceController(
        controller_model=urdf,
        tool_frame="tool",
        task_axes=("x", "y", "z", "rx", "ry", "rz"),
        normal=[0.0, 0.0, -1.0],
        config=nsdrake.ControllerConfig(period=0.001),
        fused=True,
    )
