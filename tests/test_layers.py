"""The packages keep their layers: each imports only the ones below it.

``asnn`` (arrays in, responses out) <- ``service`` (Zenoh plumbing) <- ``clients`` (viewers)
<- ``cli`` (the command line). The model's core (``asnn`` outside ``io``, ``evaluation`` and
``stimuli``) reads no files and opens no network: the command line and the evaluation hand it
frames. An import that crosses a layer upward compiles and runs, so nothing but this test
notices it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYERS = ("asnn", "service", "clients", "cli")
# what the model's core may not import: its own I/O and evaluation tooling, and any network
CORE_FORBIDDEN = ("asnn.io", "asnn.evaluation", "zenoh", "socket", "http", "urllib")


def imported_modules(path: Path) -> set[str]:
    """The absolute names of the modules a file imports (relative imports resolved against its
    package), from its syntax tree: inside functions too, since a deferred import is still a
    dependency."""
    package = path.relative_to(ROOT).with_suffix("").parts[:-1]
    if path.name == "__init__.py":
        package = path.relative_to(ROOT).parts[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = package[:len(package) - node.level + 1] if node.level else ()
            module = ".".join([*base, *([node.module] if node.module else [])])
            found.add(module)
            # ``from . import x`` names a submodule
            found.update(f"{module}.{alias.name}" for alias in node.names)
    return found


def _sources(package: str) -> list[Path]:
    return sorted((ROOT / package).rglob("*.py"))


def _within(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


@pytest.mark.parametrize("layer", LAYERS)
def test_each_layer_imports_only_the_layers_below_it(layer):
    above = LAYERS[LAYERS.index(layer) + 1:]
    assert len(_sources(layer)) > 3  # a moved or renamed package would pass unread
    crossings = [
        f"{path.relative_to(ROOT)} imports {module}"
        for path in _sources(layer)
        for module in sorted(imported_modules(path))
        if any(_within(module, upper) for upper in above)
    ]
    assert not crossings, "\n".join(crossings)


def test_the_models_core_reads_no_files_and_opens_no_network():
    tooling = [ROOT / "asnn" / name for name in ("io", "evaluation", "stimuli")]
    core = [path for path in _sources("asnn")
            if not any(path.is_relative_to(folder) for folder in tooling)]
    assert any(path.name == "model.py" for path in core)
    crossings = [
        f"{path.relative_to(ROOT)} imports {module}"
        for path in core
        for module in sorted(imported_modules(path))
        if any(_within(module, forbidden) for forbidden in CORE_FORBIDDEN)
    ]
    assert not crossings, "\n".join(crossings)


def test_the_model_imports_none_of_the_tooling_beside_it():
    """The stimuli, file I/O and evaluation sit beside the model in ``asnn/``, above it: only
    the kernels' warm-up (``asnn/warmup.py``, which steps a generated approach) reads the
    stimuli."""
    tooling = [ROOT / "asnn" / name for name in ("io", "evaluation", "stimuli")]
    core = [path for path in _sources("asnn") if path.name != "warmup.py"
            and not any(path.is_relative_to(folder) for folder in tooling)]
    crossings = [
        f"{path.relative_to(ROOT)} imports {module}"
        for path in core
        for module in sorted(imported_modules(path))
        if any(_within(module, f"asnn.{name}") for name in ("io", "evaluation", "stimuli"))
    ]
    assert not crossings, "\n".join(crossings)


def test_the_import_reader_resolves_relative_imports():
    # the reader itself must see an import written relatively (``from ..params import``), or
    # the tests above would pass whatever the code imports
    modules = imported_modules(ROOT / "asnn" / "approach" / "stage.py")
    assert {"asnn._jit", "asnn.params", "asnn.targets", "asnn.approach.looming",
            "asnn.approach.tracking", "cv2", "numpy"} <= modules


def test_the_command_line_loads_no_plotting_library_until_it_plots():
    # matplotlib takes 0.2-0.6 s to import and wants a writable cache folder: a worker or
    # camera started under systemd's sandbox (no home) logged its font-cache complaints on
    # every start when the parser's evaluation modules loaded it
    import subprocess
    import sys

    code = ("import sys\nfrom cli import main\nsys.argv = ['asnn', 'worker', '--help']\n"
            "try:\n    main.main()\nexcept SystemExit:\n    pass\n"
            "assert 'asnn.evaluation.clips' in sys.modules, 'the parser no longer loads eval'\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'matplotlib'))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"
