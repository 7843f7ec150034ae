"""The architecture, checked on the source with ast: package order, subpackage DAG, house limits.

Three rules, all read from the code (module-level *and* function-local imports,
``importlib.import_module("...")`` calls with a literal module name):

1. Packages: ``albedo_model`` <- ``proposals`` <- ``mcmcfit``; ``albedo_model``
   <- ``pipeline``; ``mcmcfit`` may also use ``pipeline`` (its CLI exposes the
   pipeline commands).
2. Subpackages: inside each package the subpackages are stacked in
   :data:`LAYERS` (bottom first). A subpackage imports only subpackages of
   strictly lower layers of its own package: no upward import, no import
   between siblings of one layer, hence no cycle. Imports across packages are
   governed by rule 1.
3. House limits (house-style.md): no module over :data:`MAX_MODULE_LINES`
   lines, no package root with more than :data:`MAX_ROOT_MODULES` modules.

``python -m pytest tests/test_architecture.py -s`` prints the DAG as it is in
the code (each subpackage -> what it imports). docs/architecture.md describes
the same DAG in prose; change both together.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from functools import cache
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]

#: Rule 1: which project packages each package may import.
ALLOWED = {
    "albedo_model": {"albedo_model"},
    "proposals": {"albedo_model", "proposals"},
    "pipeline": {"albedo_model", "pipeline"},
    "mcmcfit": {"albedo_model", "proposals", "pipeline", "mcmcfit"},
}

#: Rule 2: the intended subpackage order, bottom layer first. A unit is a
#: subpackage (``mcmcfit.fitting``) or a package's root modules (``mcmcfit``:
#: the modules directly in ``mcmcfit/``). A module belongs to the longest unit
#: that prefixes its name.
#:
#: - ``albedo_model``: the root modules (params, model, pca, camera, sh, errors,
#:   default_model) are the bottom; shading is pure JAX over them; the
#:   renderer (ray casting + caches) drives shading; the file formats read and
#:   write the root types; textures are baked with the ray caster.
#: - ``pipeline``: texturing and modelling are independent tools; the
#:   lightstage processing uses both; the synthetic lightstage (head, then
#:   subjects and capture simulator) builds on the real lightstage code.
#: - ``mcmcfit``: the sampler, then the targets (likelihoods, priors) and the
#:   proposal data (albedo conditional, light estimate), the fit that runs them,
#:   the outputs of a fit, the job (files in, result folder out), batch and
#:   benchmarks over jobs, the commands, and at the top the package root (CLI,
#:   ``python -m mcmcfit``, the public facade ``mcmcfit/__init__.py``).
LAYERS: dict[str, list[list[str]]] = {
    "albedo_model": [
        ["albedo_model"],
        ["albedo_model.shading"],
        ["albedo_model.render", "albedo_model.io"],
        ["albedo_model.texture"],
    ],
    "proposals": [
        ["proposals"],
        ["proposals.laplace"],
    ],
    "pipeline": [
        ["pipeline", "pipeline.texturing", "pipeline.modelling"],
        ["pipeline.lightstage"],
        ["pipeline.synthetic.head"],
        ["pipeline.synthetic"],
    ],
    "mcmcfit": [
        ["mcmcfit.sampling", "mcmcfit.detection"],
        ["mcmcfit.targets", "mcmcfit.proposal_data"],
        ["mcmcfit.fitting"],
        ["mcmcfit.outputs"],
        ["mcmcfit.jobs"],
        ["mcmcfit.batch", "mcmcfit.bench"],
        ["mcmcfit.evaluation"],
        ["mcmcfit.commands"],
        ["mcmcfit"],
    ],
}

#: ``__main__`` modules are entry points (``python -m mcmcfit.bench`` is
#: ``mcmcfit bench``): nothing imports them, so they belong to the top unit of
#: their package, the command line.
ENTRY_POINT = "__main__"

#: Rule 3 (house-style.md: "modules under ~400 lines"; a package root stays a
#: short list). Nothing is allow-listed.
MAX_MODULE_LINES = 400
MAX_ROOT_MODULES = 12

LAYER_OF = {unit: (pkg, i) for pkg, layers in LAYERS.items()
            for i, layer in enumerate(layers) for unit in layer}


# --------------------------------------------------------------------------- reading the code

def module_name(path: Path) -> str:
    """Dotted module name of a source file under REPO (``pkg/__init__.py`` -> ``pkg``)."""
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def source_files(package: str) -> list[Path]:
    return sorted((REPO / package).rglob("*.py"))


def _is_module(dotted: str) -> bool:
    p = REPO.joinpath(*dotted.split("."))
    return p.with_suffix(".py").is_file() or (p / "__init__.py").is_file()


def _literal_module(node: ast.expr) -> str | None:
    """Module named by ``import_module("a.b")`` or ``import_module(f"a.b.{x}")`` (-> ``a.b``)."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr) and node.values and isinstance(node.values[0], ast.Constant):
        prefix = str(node.values[0].value)
        return prefix.rsplit(".", 1)[0] if "." in prefix else None
    return None


@cache
def imports_of(path: Path) -> tuple[tuple[int, str, bool], ...]:
    """``(line, module, bare)`` for every project import in a file, wherever it sits.

    ``from a.b import c`` counts as ``a.b.c`` when ``c`` is a module, else as
    ``a.b``. A bare ``import pkg`` of a package's own top level adds nothing
    (Python runs ``pkg/__init__.py`` before any of its submodules anyway): it
    is flagged ``bare`` and counts for rule 1 only.
    """
    tree = ast.parse(path.read_text(), filename=str(path))
    here = module_name(path).split(".")
    is_pkg = path.name == "__init__.py"
    found: list[tuple[int, str, bool]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name, a.name in ALLOWED) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against this module's package
                base = here if is_pkg else here[:-1]
                base = base[: len(base) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            subs = [f"{module}.{a.name}" for a in node.names if _is_module(f"{module}.{a.name}")]
            if subs:
                found += [(node.lineno, s, False) for s in subs]
            if len(subs) < len(node.names):
                found.append((node.lineno, module, False))
        elif isinstance(node, ast.Call) and node.args:
            fn = node.func
            name = fn.attr if isinstance(fn, ast.Attribute) else getattr(fn, "id", "")
            if name in ("import_module", "__import__"):
                module = _literal_module(node.args[0])
                if module:
                    found.append((node.lineno, module, False))
    return tuple(f for f in found if f[1].split(".")[0] in ALLOWED)


def unit_of(module: str) -> str:
    """The unit (LAYERS entry) a dotted module belongs to; KeyError if none does."""
    parts = module.split(".")
    if parts[-1] == ENTRY_POINT:
        return LAYERS[parts[0]][-1][0]
    for n in range(len(parts), 0, -1):
        if ".".join(parts[:n]) in LAYER_OF:
            return ".".join(parts[:n])
    raise KeyError(module)


def units_on_disk(package: str) -> set[str]:
    """Every unit the tree has: the package root and each directory holding modules."""
    found = {package}
    for path in source_files(package):
        if path.parent != REPO / package:
            found.add(module_name(path.parent / "__init__.py"))
    return found


@cache
def unit_graph() -> dict[str, dict[str, list[str]]]:
    """unit -> imported unit (any package) -> ``["file:line module", ...]``."""
    graph: dict[str, dict[str, list[str]]] = defaultdict(lambda: defaultdict(list))
    for package in LAYERS:
        for path in source_files(package):
            src = unit_of(module_name(path))
            graph[src]  # every unit is listed, even one that imports nothing
            for line, module, bare in imports_of(path):
                if bare:  # ``import pkg``: no dependency (see imports_of)
                    continue
                dst = unit_of(module)
                if dst != src:
                    graph[src][dst].append(f"{path.relative_to(REPO)}:{line} imports {module}")
    return {k: dict(v) for k, v in graph.items()}


def label(unit: str) -> str:
    return f"{unit}(root)" if unit in LAYERS else unit


def against_layers(src: str, dst: str) -> str | None:
    """``"upward"`` / ``"sibling"`` if ``src -> dst`` breaks rule 2, else None."""
    (p_src, l_src), (p_dst, l_dst) = LAYER_OF[src], LAYER_OF[dst]
    if p_src != p_dst or l_dst < l_src:
        return None
    return "sibling" if l_dst == l_src else "upward"


def render_dag() -> str:
    """The DAG as text: per package, bottom layer first, each unit -> what it imports."""
    graph = unit_graph()
    lines = ["Subpackage DAG, read from the code (X(root) = the modules directly in X/;",
             "layers bottom first, '<-' = 'is imported by'; '!' marks an import against LAYERS):"]
    for package, layers in LAYERS.items():
        lines.append("")
        order = "  <-  ".join(", ".join(map(label, layer)) for layer in layers)
        lines.append(f"{package}: {order}")
        for layer in layers:
            for unit in layer:
                deps = graph.get(unit, {})
                own = [label(d) + ("!" if against_layers(unit, d) else "")
                       for d in sorted(deps) if d.split(".")[0] == package]
                other = [label(d) for d in sorted(deps) if d.split(".")[0] != package]
                text = ", ".join(own) if own else "-"
                if other:
                    text += "   [+ " + ", ".join(other) + "]"
                lines.append(f"  {label(unit):26s} -> {text}")
    return "\n".join(lines)


def find_cycle(graph: dict[str, dict[str, list[str]]]) -> list[str] | None:
    """One cycle of the graph as a node list (first == last), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, {})):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


# --------------------------------------------------------------------------- rule 1

def imported_project_packages(path: Path) -> set[str]:
    return {module.split(".")[0] for _, module, _ in imports_of(path)}


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_dependency_direction(package):
    bad = {}
    for path in source_files(package):
        extra = imported_project_packages(path) - ALLOWED[package]
        if extra:
            bad[str(path.relative_to(REPO))] = sorted(extra)
    assert not bad, f"forbidden imports: {bad}"


# --------------------------------------------------------------------------- rule 2

def test_print_dag():
    text = render_dag()
    print("\n" + text)
    assert all(unit in text for unit in LAYER_OF)


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_every_subpackage_has_a_layer(package):
    missing = sorted(units_on_disk(package) - set(LAYER_OF))
    assert not missing, f"subpackages not placed in LAYERS (add them, bottom first): {missing}"


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_no_upward_import(package):
    bad = []
    for src, deps in unit_graph().items():
        if LAYER_OF[src][0] != package:
            continue
        for dst, where in sorted(deps.items()):
            kind = against_layers(src, dst)
            if kind:
                bad += [f"{kind} {label(src)} -> {label(dst)}: {w}" for w in where]
    assert not bad, "imports against LAYERS:\n" + "\n".join(bad)


def test_no_cycle():
    cycle = find_cycle(unit_graph())
    assert cycle is None, "import cycle between units: " + " -> ".join(cycle)


def test_layers_are_a_partition():
    units = [u for layers in LAYERS.values() for layer in layers for u in layer]
    assert len(units) == len(set(units))
    assert all(u.split(".")[0] == pkg for pkg, layers in LAYERS.items()
               for layer in layers for u in layer)


# --------------------------------------------------------------------------- rule 3

@pytest.mark.parametrize("package", sorted(LAYERS))
def test_module_size(package):
    long = {str(p.relative_to(REPO)): n for p in source_files(package)
            if (n := len(p.read_text().splitlines())) > MAX_MODULE_LINES}
    assert not long, f"modules over {MAX_MODULE_LINES} lines: {long}"


@pytest.mark.parametrize("package", sorted(LAYERS))
def test_package_root_size(package):
    modules = sorted(p.name for p in (REPO / package).glob("*.py") if p.name != "__init__.py")
    assert len(modules) <= MAX_ROOT_MODULES, (
        f"{package}/ has {len(modules)} modules (at most {MAX_ROOT_MODULES}): {modules}")
