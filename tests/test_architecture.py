"""The package layout's rules: imports flow one way, no cycles, light top-level imports."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("envs", "localization", "agents")

#: lowest layer first; a module may import only from its own layer or lower ones
LAYERS: list[tuple[str, ...]] = [
    ("localization", "localization.geometry", "localization._lazy", "localization._validation",
     "localization.recorded", "localization._tum"),
    ("envs",),
    ("localization.features",),
    ("localization.gse", "localization.metrics", "localization.model_selection",
     "localization.baselines", "localization.intrinsic_dim", "localization.intrinsic_dim_geodesic",
     "localization.synthetic"),
    ("localization.filtering",),
    ("localization.localizer", "localization._localizer_io", "localization._localizer_noise",
     "localization._localizer_map", "localization._localizer_belief",
     "localization.districts", "localization._districts_noise", "localization._districts_io",
     "localization._district_maps", "localization._localizer_features",
     "localization.experiences",
     "localization.loading",
     "localization.wrappers", "localization.wrapper_render", "localization.belief_render",
     "localization.wrapper_checks", "localization.familiarity"),
    ("agents",),
    ("localization.workflows",),
    ("localization.cli",),
]


def _layer(module: str) -> int:
    """Index of the most specific layer prefix of ``module``."""
    best, best_len = -1, -1
    for i, prefixes in enumerate(LAYERS):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best_len:
                best, best_len = i, len(p)
    if best < 0:
        raise AssertionError(f"module {module} is in no layer of LAYERS")
    return best


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _imports(path: Path) -> set[str]:
    """Project modules imported anywhere in the file (top level or inside functions)."""
    name = _module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    out = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                pkg = package.split(".")
                base = ".".join(pkg[: len(pkg) - node.level + 1] + ([base] if base else []))
            out.add(base)
            out |= {f"{base}.{a.name}" for a in node.names}
    return {m for m in out if m.split(".")[0] in PACKAGES and _exists(m)}


def _exists(module: str) -> bool:
    p = ROOT.joinpath(*module.split("."))
    return p.with_suffix(".py").is_file() or (p / "__init__.py").is_file()


def _graph() -> dict[str, set[str]]:
    files = [f for pkg in PACKAGES for f in (ROOT / pkg).rglob("*.py")]
    return {_module_name(f): _imports(f) - {_module_name(f)} for f in files}


def test_every_module_is_in_a_layer():
    for module in _graph():
        _layer(module)


def test_no_upward_import():
    upward = [f"{m} (layer {_layer(m)}) imports {d} (layer {_layer(d)})"
              for m, deps in _graph().items() for d in deps
              if _layer(d) > _layer(m) and not m.startswith(d + ".")
              and not (m.count(".") == 0 and d.startswith(m + "."))]
    assert not upward, "\n".join(upward)


def test_localization_imports_envs_only_in_its_workflow_layer():
    """Features, GSE and filters run without the simulator; the command line reaches it
    through the workflows too."""
    bad = [f"{m} imports {d}" for m, deps in _graph().items() for d in deps
           if m.startswith("localization") and d.split(".")[0] == "envs"
           and not m.startswith("localization.workflows")]
    assert not bad, "\n".join(bad)


def test_no_import_cycle():
    g = _graph()
    # a package's __init__ re-exporting its own submodules is not a cycle of concepts
    edges = {m: {d for d in deps if not d.startswith(m + ".")} for m, deps in g.items()}
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for d in sorted(edges.get(m, ())):
            if state.get(d) == 1:
                cycle = stack[stack.index(d):] + [d]
                pytest.fail("import cycle: " + " -> ".join(cycle))
            if d not in state:
                visit(d)
        stack.pop()
        state[m] = 2

    for m in sorted(edges):
        if m not in state:
            visit(m)


@pytest.mark.parametrize("module", ["localization", "localization.filtering",
                                    "localization.gse", "localization.geometry",
                                    "localization.features"])
def test_import_is_light(module):
    """The toolkit runs on recorded data: neither MuJoCo nor torch is imported."""
    code = (f"import sys, {module}; "
            "print(','.join(m for m in ('mujoco', 'torch', 'gymnasium') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         cwd=ROOT, check=True).stdout.strip()
    heavy = set(filter(None, out.split(",")))
    assert not heavy & {"mujoco", "torch"}, f"import {module} loaded {heavy}"
    if module != "localization.features":
        assert "gymnasium" not in heavy, f"import {module} loaded {heavy}"


def test_public_names_resolve():
    import agents
    import localization
    import localization.workflows

    for pkg in (localization, agents, localization.workflows):
        for name in pkg.__all__:
            assert getattr(pkg, name) is not None, f"{pkg.__name__}.{name}"


def test_all_lists_exactly_the_lazy_names():
    import agents
    import localization
    import localization.workflows

    for pkg in (localization, agents, localization.workflows):
        assert sorted(pkg.__all__) == sorted(pkg._LAZY), pkg.__name__
