"""The README's examples run as written.

Every ```python block of README.md runs, in order, in one fresh interpreter (a subprocess in a
temporary folder, so ``results/`` and ``data/`` start empty, as on a fresh checkout), with
``APPEARANCE_NAV_QUICK=1``, which the blocks honour visibly to shrink their fits. The agents
block loads ``results/localizer.npz``, the street-wide localizer that ``make demo`` writes; CI
runs only ``make test``, so the runner stands in for ``make demo``: it creates ``results/``
and copies the quick start's (smaller) street-wide localizer there when the demo's is missing. Shell blocks are not run (they
train for minutes): each ``appearance-nav`` line must name a real command and each ``make``
line a real target.
"""

from __future__ import annotations

import builtins
import json
import os
import re
import subprocess
import symtable
import sys
from pathlib import Path

import pytest

from localization.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.DOTALL | re.MULTILINE)

# Runs the blocks in one namespace; a failing block prints its number and the error.
RUNNER = r'''
import json, shutil, sys, time, traceback
from pathlib import Path

blocks = json.loads(Path(sys.argv[1]).read_text())
namespace = {"__name__": "__main__"}
demo, quick = Path("results/localizer.npz"), Path("results/quickstart_localizer.npz")
demo.parent.mkdir(exist_ok=True)  # stands in for `make demo`, which writes results/
for i, code in enumerate(blocks, 1):
    if not demo.exists() and quick.exists():  # stands in for `make demo` (see the test)
        shutil.copy(quick, demo)
    t0 = time.perf_counter()
    try:
        exec(compile(code, f"README python block {i}", "exec"), namespace)
    except BaseException:
        print(f"README python block {i} of {len(blocks)} failed:", file=sys.stderr)
        traceback.print_exc()
        sys.exit(1)
    print(f"README python block {i} ran ({time.perf_counter() - t0:.1f} s)", flush=True)
'''


def blocks(language: str) -> list[str]:
    """The README's fenced code blocks in ``language``, in order."""
    return [body for lang, body in FENCE.findall(README.read_text()) if lang == language]


def free_names(code: str) -> set[str]:
    """Global names a block reads but neither defines nor imports (nor are builtins)."""
    top = symtable.symtable(code, "block", "exec")
    defined = {s.get_name() for s in top.get_symbols() if s.is_assigned() or s.is_imported()}
    used: set[str] = set()

    def visit(table: symtable.SymbolTable) -> None:
        for s in table.get_symbols():
            if s.is_referenced() and (s.is_global() or table is top):
                used.add(s.get_name())
        for child in table.get_children():
            visit(child)

    visit(top)
    return used - defined - set(dir(builtins))


def test_readme_has_the_quick_start_first() -> None:
    shell = blocks("bash")
    assert shell and shell[0].split("\n")[0].startswith("make demo"), "README opens with make demo"
    assert "make test" in shell[0]
    first = blocks("python")[0]
    for name in ("gym.make", "fit_city_localizer", "BeliefWrapper", "ScriptedAgent"):
        assert name in first, f"the quick start shows {name}"


@pytest.mark.parametrize("number", range(1, len(blocks("python")) + 1))
def test_python_block_is_self_contained(number: int) -> None:
    """Each block imports what it uses, so it also runs on its own (given the files)."""
    missing = free_names(blocks("python")[number - 1])
    assert not missing, f"README python block {number} uses undefined names {sorted(missing)}"


def test_shell_blocks_name_real_commands() -> None:
    targets = set(re.findall(r"^([\w-]+):", (ROOT / "Makefile").read_text(), re.MULTILINE))
    lines = [ln.strip() for b in blocks("bash") for ln in b.splitlines() if ln.strip()]
    assert lines
    for line in lines:
        assert not re.match(r"python3?\s", line), f"bare python (use .venv/bin/python): {line}"
        assert "scripts/" not in line, f"a script instead of appearance-nav: {line}"
        if line.startswith("make "):
            assert line.split()[1] in targets, f"unknown make target: {line}"
            continue
        m = re.match(r"(?:\.venv/bin/)?appearance-nav(?:\s+(\S+))?", line)
        assert m, f"shell line is neither make nor appearance-nav: {line}"
        if m.group(1) and m.group(1) != "--help":
            assert m.group(1) in COMMANDS, f"unknown appearance-nav command: {line}"
    for name in re.findall(r"appearance-nav ([a-z]+)", README.read_text()):
        assert name in COMMANDS, f"README names an unknown command appearance-nav {name}"


def test_no_two_blocks_write_the_same_file() -> None:
    written: dict[str, int] = {}
    pattern = re.compile(r"""(?:save(?:_dataset)?\(|--out\s+)["']?([\w./-]+\.npz)""")
    for i, code in enumerate(blocks("python") + blocks("bash"), 1):
        for path in set(pattern.findall(code)):
            assert path not in written, f"blocks {written[path]} and {i} both write {path}"
            written[path] = i
    assert "results/localizer.npz" not in written, "the README overwrites the demo's localizer"


def test_python_blocks_run_in_order(tmp_path: Path) -> None:
    code = blocks("python")
    (tmp_path / "blocks.json").write_text(json.dumps(code))
    (tmp_path / "runner.py").write_text(RUNNER)
    env = {**os.environ, "APPEARANCE_NAV_QUICK": "1", "MPLBACKEND": "Agg",
           "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.run([sys.executable, "runner.py", "blocks.json"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    ran = proc.stdout.count(" ran (")
    assert proc.returncode == 0, f"{proc.stdout}{ran} of {len(code)} blocks ran; then:\n" \
        f"{proc.stderr[-4000:]}"
    assert ran == len(code)
    assert (tmp_path / "results" / "route_localizer.npz").is_file()
    assert (tmp_path / "data" / "route.npz").is_file()


def slug(heading: str) -> str:
    """GitHub's anchor of a markdown heading."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower().replace("\\", ""))
    return text.replace(" ", "-")


@pytest.mark.parametrize("page", ["README.md", "docs/method.md", "docs/results.md",
                                  "docs/benchmarks.md", "docs/CONTRACTS.md",
                                  "docs/targets.md"])
def test_links_resolve(page: str) -> None:
    """Relative links name files that exist and headings that exist in them."""
    path = ROOT / page
    for target in re.findall(r"\]\(([^)\s]+)\)", path.read_text()):
        if re.match(r"\w+://", target):
            continue
        file, _, anchor = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        assert dest.exists(), f"{page} links to a missing file {target}"
        if anchor:
            heads = re.findall(r"^#+ (.*)$", dest.read_text(), re.MULTILINE)
            assert anchor in {slug(h) for h in heads}, f"{page}: no heading for #{anchor}"
