"""Every file a model is made of, read before Drake parses it.

A model file may include others: Drake model directives add URDF, SDF and further
directives files (``add_model``, ``add_directives``), an SDF ``<include>``\\s models. Drake
reads the whole tree; so do the rules here, each file in turn (:func:`read_sources`):

- an include cycle (a directives file that adds itself, directly or through others) is
  refused in one line naming the chain (Drake would recurse until the process crashes);
- every URDF and SDF file gets the physical checks of
  :mod:`nsdrake.control.urdf_checks` (Drake only warns about a massless or impossible link
  in an included file, and simulates a "repaired" one);
- a ``floating`` joint between two links of a URDF is refused, naming it (Drake drops it,
  and then blames whatever else names the joint);
- what the files declare that Drake's plant does not take is collected: ``<limit effort>``
  of each joint (an actuator comes only from a ``<transmission>``) and ``<mimic>`` joints;
- collision meshes in a format Drake cannot take the convex hull of (STL, DAE, ...):
  :func:`hull_model` writes a copy of the tree in which each such mesh is replaced by its
  convex hull as an OBJ file (read with trimesh), which Drake uses for distance queries
  and point contact anyway (an ``.obj`` collision mesh is used as its convex hull). The
  dynamics never need geometry; a plant without a SceneGraph parses the files as shipped.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from nsdrake.control.urdf_checks import sdf_problems, urdf_problems
from nsdrake.control.validation import ControllerConfigError, one_line

# Mesh formats whose convex hull Drake computes itself (Drake's MakeConvexHull).
HULL_FORMATS = (".obj", ".vtk", ".gltf")


@dataclass
class SourceFile:
    """One file of a model: ``path``, its ``kind`` (urdf, sdf, directives) and the files it
    includes (resolved paths)."""

    path: Path
    kind: str
    includes: list[Path] = field(default_factory=list)


@dataclass
class Mimic:
    """A URDF ``<mimic>``: q_joint = multiplier q_leader + offset."""

    joint: str
    leader: str
    multiplier: float
    offset: float


@dataclass
class ModelSources:
    """What :func:`read_sources` found in a model's files."""

    files: list[SourceFile]  # every file, the top one first
    efforts: dict[str, float]  # joint name -> its <limit effort> (> 0) [N m or N]
    mimics: dict[str, Mimic]  # follower joint name -> its mimic
    meshes_to_hull: list[Path]  # collision meshes in a format Drake takes no hull of


def kind_of(path: Path) -> str:
    name = path.name.lower()
    if name.endswith(".dmd.yaml"):
        return "directives"
    return "sdf" if name.endswith(".sdf") else "urdf"


def resolve_uri(uri: str, folder: Path, package_map) -> Path | None:
    """The file a model URI names (package://, model://, file://, or relative to ``folder``),
    or None when the package is unknown (Drake says so when it parses)."""
    uri = uri.strip()
    for scheme in ("package://", "model://"):
        if uri.startswith(scheme):
            name, _, rest = uri[len(scheme) :].partition("/")
            if not package_map.Contains(name):
                return None
            return Path(package_map.GetPath(name)) / rest
    if uri.startswith("file://"):
        return Path(uri[len("file://") :])
    return folder / uri


def read_sources(path: Path, package_map, where: str) -> ModelSources:
    """The model's files from ``path`` down (module docstring), each checked; every problem a
    one-line ControllerConfigError naming ``where`` and the file."""
    sources = ModelSources(files=[], efforts={}, mimics={}, meshes_to_hull=[])
    _visit(Path(path).resolve(), [], package_map, where, sources, set())
    return sources


def _visit(path: Path, chain: list[Path], package_map, where, sources: ModelSources, seen: set) -> None:
    if path in chain:
        cycle = " → ".join(p.name for p in [*chain[chain.index(path) :], path])
        raise ControllerConfigError(
            f"{where}: {chain[0].name}",
            f"an include cycle ({cycle}): Drake would include it until the process crashes",
        )
    if path in seen:
        return
    seen.add(path)
    kind = kind_of(path)
    source = SourceFile(path, kind)
    sources.files.append(source)
    here = f"{where}: {path.name}"
    if not path.is_file():
        raise ControllerConfigError(
            f"{where}: {chain[-1].name if chain else path.name}", f"includes {path}, not a file"
        )
    if kind == "directives":
        source.includes = _directive_includes(path, package_map, here)
    else:
        try:
            root = ET.parse(path).getroot()
        except (ET.ParseError, OSError) as e:
            raise ControllerConfigError(here, f"not readable XML: {one_line(e)}") from None
        problems = urdf_problems(root) if kind == "urdf" else sdf_problems(root)
        for element, problem in problems:
            raise ControllerConfigError(f"{here}: {element}", problem)
        if kind == "urdf":
            _urdf_declarations(root, here, sources)
        else:
            _sdf_declarations(root, sources)
            for uri in root.iter("include"):
                target = resolve_uri((uri.findtext("uri") or "").strip(), path.parent, package_map)
                if target is not None and target.is_dir():
                    target = target / "model.sdf"
                if target is not None:
                    source.includes.append(target.resolve())
        for mesh in _collision_meshes(root, kind):
            target = resolve_uri(mesh, path.parent, package_map)
            if target is not None and target.suffix.lower() not in HULL_FORMATS:
                sources.meshes_to_hull.append(target)
    for child in source.includes:
        _visit(child, [*chain, path], package_map, where, sources, seen)


class _Tagged:
    """A value under one of Drake's YAML tags (``!Rpy {deg: [...]}``, ``!AngleAxis``): kept
    as written, so that a directives file read here and written again says the same."""

    def __init__(self, tag: str, value):
        self.tag, self.value = tag, value


class _DirectivesLoader(yaml.SafeLoader):
    """YAML's safe loader that takes Drake's tags (:class:`_Tagged`)."""


def _construct_tagged(loader, suffix, node):
    if isinstance(node, yaml.MappingNode):
        value = loader.construct_mapping(node, deep=True)
    elif isinstance(node, yaml.SequenceNode):
        value = loader.construct_sequence(node, deep=True)
    else:
        value = loader.construct_scalar(node)
    return _Tagged("!" + suffix, value)


_DirectivesLoader.add_multi_constructor("!", _construct_tagged)


class _DirectivesDumper(yaml.SafeDumper):
    """YAML's safe dumper that writes :class:`_Tagged` back under its tag."""


def _represent_tagged(dumper, tagged: _Tagged):
    if isinstance(tagged.value, dict):
        return dumper.represent_mapping(tagged.tag, tagged.value)
    if isinstance(tagged.value, list):
        return dumper.represent_sequence(tagged.tag, tagged.value)
    return dumper.represent_scalar(tagged.tag, str(tagged.value))


_DirectivesDumper.add_representer(_Tagged, _represent_tagged)


def _read_directives(path: Path):
    return yaml.load(path.read_text(), Loader=_DirectivesLoader)  # noqa: S506 (a safe loader with tags)


def _directive_includes(path: Path, package_map, here: str) -> list[Path]:
    try:
        data = _read_directives(path)
    except (yaml.YAMLError, OSError, UnicodeDecodeError) as e:
        raise ControllerConfigError(here, f"not readable YAML: {one_line(e)}") from None
    out = []
    directives = data.get("directives", []) if isinstance(data, dict) else []
    for item in directives if isinstance(directives, list) else []:
        for key in ("add_model", "add_directives"):
            entry = item.get(key) if isinstance(item, dict) else None
            uri = entry.get("file") if isinstance(entry, dict) else None
            if isinstance(uri, str):
                target = resolve_uri(uri, path.parent, package_map)
                if target is not None:
                    out.append(target.resolve())
    return out


def _urdf_declarations(root: ET.Element, here: str, sources: ModelSources) -> None:
    for joint in root.findall("joint"):
        name = joint.get("name", "")
        if joint.get("type") == "floating":
            parent, child = _link_of(joint, "parent"), _link_of(joint, "child")
            if parent != "world":
                raise ControllerConfigError(
                    f"{here}: joint '{name}'",
                    f"a floating joint inside the arm (between '{parent}' and '{child}'): nsdrake's arms "
                    "have revolute, continuous, prismatic and fixed joints; make it one of these",
                )
        limit = joint.find("limit")
        effort = _float(limit.get("effort")) if limit is not None else None
        if effort is not None and effort > 0 and name not in sources.efforts:
            sources.efforts[name] = effort
        mimic = joint.find("mimic")
        if mimic is not None:
            sources.mimics[name] = Mimic(
                name,
                mimic.get("joint", ""),
                _float(mimic.get("multiplier")) if mimic.get("multiplier") else 1.0,
                _float(mimic.get("offset")) if mimic.get("offset") else 0.0,
            )


def _link_of(joint: ET.Element, tag: str) -> str:
    element = joint.find(tag)
    return "" if element is None else element.get("link", "")


def _sdf_declarations(root: ET.Element, sources: ModelSources) -> None:
    for joint in root.iter("joint"):
        effort = _float(joint.findtext("axis/limit/effort"))
        if effort is not None and effort > 0:
            sources.efforts.setdefault(joint.get("name", ""), effort)


def _float(text) -> float | None:
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def _collision_meshes(root: ET.Element, kind: str) -> list[str]:
    if kind == "urdf":
        return [m.get("filename", "") for c in root.iter("collision") for m in c.iter("mesh")]
    return [(m.findtext("uri") or "") for c in root.iter("collision") for m in c.iter("mesh")]


# ---------------------------------------------------------------- convex hulls


def cache_folder() -> Path:
    """Where hulls are kept: $NSDRAKE_CACHE, else $XDG_CACHE_HOME/nsdrake, else ~/.cache/nsdrake."""
    if os.environ.get("NSDRAKE_CACHE"):
        return Path(os.environ["NSDRAKE_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "nsdrake"


def convex_hull_obj(mesh: Path, where: str) -> Path:
    """An OBJ file of ``mesh``'s convex hull (in the mesh file's own units, its scene's
    transforms applied), read with trimesh; kept in the cache under the mesh's content hash."""
    data = mesh.read_bytes()
    digest = hashlib.sha256(data + mesh.suffix.lower().encode()).hexdigest()[:32]
    out = cache_folder() / "hulls" / f"{digest}.obj"
    if out.is_file():
        return out
    import trimesh

    try:
        loaded = trimesh.load(str(mesh), force="mesh", process=False)
        hull = trimesh.convex.convex_hull(loaded.vertices)
    except Exception as e:  # trimesh raises many kinds for a file that is not a mesh
        raise ControllerConfigError(
            where, f"cannot read the collision mesh {mesh.name}: {one_line(e)}"
        ) from None
    temporary = out.with_suffix(f".{os.getpid()}.tmp")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        temporary.write_text(
            trimesh.exchange.obj.export_obj(hull, include_normals=False, include_texture=False)
        )
        temporary.replace(out)  # atomic: another process may write the same hull
    except OSError as e:
        raise ControllerConfigError(
            where,
            f"cannot keep the convex hull of {mesh.name} in {out.parent} ({one_line(e)}): "
            "set NSDRAKE_CACHE to a folder you can write",
        ) from None
    return out


class HulledModel:
    """A copy of the model's tree (URDF, SDF, directives) in a temporary folder, each
    collision mesh Drake takes no hull of replaced by its hull's OBJ and every other URI
    made absolute (without ``visuals``, the visual elements left out: a controller's model
    draws nothing, and Drake refuses some vendors' visuals, the Jaco's material defined
    twice in two colours); :attr:`top` is the copy of the top file. A context manager: the copies
    are removed on exit (the hulls stay in the cache)."""

    def __init__(self, sources: ModelSources, package_map, where: str, visuals: bool = True):
        self.folder = Path(tempfile.mkdtemp(prefix="nsdrake-model-"))
        self.originals: dict[Path, Path] = {}
        copies = {f.path: self.folder / f"{i}_{f.path.name}" for i, f in enumerate(sources.files)}
        for f in sources.files:
            text = _rewritten(f, copies, package_map, where, visuals)
            copies[f.path].write_text(text)
            self.originals[copies[f.path]] = f.path
        self.top = copies[sources.files[0].path]

    def __enter__(self) -> HulledModel:
        return self

    def __exit__(self, *_) -> None:
        shutil.rmtree(self.folder, ignore_errors=True)

    def original_text(self, text: str) -> str:
        """``text`` with the copies' paths replaced by the files they copy."""
        for copy, original in self.originals.items():
            text = text.replace(str(copy), str(original))
        return text


def _rewritten(f: SourceFile, copies: dict, package_map, where: str, visuals: bool = True) -> str:
    if f.kind == "directives":
        data = _read_directives(f.path)
        for item in data.get("directives", []):
            for key in ("add_model", "add_directives"):
                entry = item.get(key) if isinstance(item, dict) else None
                if isinstance(entry, dict) and isinstance(entry.get("file"), str):
                    target = resolve_uri(entry["file"], f.path.parent, package_map)
                    if target is not None and target.resolve() in copies:
                        entry["file"] = "file://" + str(copies[target.resolve()])
        return yaml.dump(data, Dumper=_DirectivesDumper, sort_keys=False)
    tree = ET.parse(f.path)
    root = tree.getroot()
    if not visuals:
        for parent in list(root.iter()):
            for child in [c for c in parent if c.tag == "visual"]:
                parent.remove(child)
    if f.kind == "urdf":
        for role in ("collision", "visual"):
            for element in root.iter(role):
                for mesh in element.iter("mesh"):
                    mesh.set("filename", _uri(mesh.get("filename", ""), role, f, package_map, where))
    else:
        for role in ("collision", "visual"):
            for element in root.iter(role):
                for uri in element.iter("uri"):
                    uri.text = _uri(uri.text or "", role, f, package_map, where)
        for include in root.iter("include"):
            uri = include.find("uri")
            target = resolve_uri((uri.text or "") if uri is not None else "", f.path.parent, package_map)
            if target is not None and target.is_dir():
                target = target / "model.sdf"
            if target is not None and target.resolve() in copies:
                uri.text = "file://" + str(copies[target.resolve()])
    return ET.tostring(root, encoding="unicode")


def _uri(uri: str, role: str, f: SourceFile, package_map, where: str) -> str:
    """The URI as the copy must say it: absolute (the copy lives elsewhere), and a collision
    mesh Drake takes no hull of replaced by its hull's OBJ."""
    target = resolve_uri(uri, f.path.parent, package_map)
    if target is None:
        return uri  # an unknown package: Drake names it
    if role == "collision" and target.suffix.lower() not in HULL_FORMATS and target.is_file():
        return str(convex_hull_obj(target, f"{where}: {f.path.name}"))
    return uri if uri.startswith(("package://", "model://")) else str(target.resolve())
