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


# what a process that runs no model may not load: numba and the model (a router held 145 MB
# when the parser imported every command's module, 63 MB without them), OpenCV, the evaluation's tooling, and
# matplotlib (0.2-0.6 s to import, and a writable cache folder wanted: a worker or camera
# started under systemd's sandbox, no home, logged its font-cache complaints on every start)
MODEL_FREE = ("numba", "llvmlite", "cv2", "asnn.model", "asnn.evaluation.runs",
              "asnn.evaluation.scoring", "asnn.evaluation.perturb", "matplotlib")


@pytest.mark.parametrize("argv", [["--help"], ["router", "--help"], ["status", "--help"],
                                  ["alerts", "--help"], ["eval", "--help"],
                                  ["worker", "--help"], ["detect", "--help"]])
def test_the_parser_and_the_commands_without_a_model_load_none_of_it(argv):
    """Every command builds the whole parser: it takes its choices and defaults from modules
    that load no model (asnn.params, asnn.evaluation.options, the service's constants), and a
    command imports what it runs when it runs. ``asnn router``, ``status`` and ``alerts`` run
    without the model: the modules they run are imported here too."""
    import subprocess
    import sys

    code = ("import sys\nfrom cli import main\n"
            f"sys.argv = ['asnn', *{argv!r}]\n"
            "try:\n    main.main()\nexcept SystemExit:\n    pass\n"
            "import clients.alerts, service.router, service.worker\n"
            "assert 'asnn.params' in sys.modules, 'the parser reads the presets no more'\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('numba', 'llvmlite', "
            "'cv2', 'matplotlib') or m in " + repr(MODEL_FREE) + "))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, check=True).stdout
    assert out.strip().splitlines()[-1] == "[]"


def test_a_command_still_loads_what_it_runs():
    # the model's modules are imported by the command that runs them (a worker's WorkerCore
    # makes its detector), so that the check above cannot pass by a command losing them
    import subprocess
    import sys

    code = ("import sys\nfrom service.core import WorkerCore\nWorkerCore('asnn', None)\n"
            "print('asnn.model' in sys.modules, 'numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         timeout=120, check=True).stdout
    assert out.split() == ["True", "True"]


def test_the_parser_keeps_the_choices_and_defaults_it_takes_from_the_model_and_the_evaluation():
    # read from the modules named above without importing their tooling: the same values
    from asnn.detectors import MODELS, available_cores
    from asnn.evaluation.heldout import TIE_BREAKS
    from asnn.evaluation.perturb import FAMILIES
    from asnn.evaluation.runs import DEFAULT_DETECTORS
    from asnn.io.video import FPS_RANGE
    from cli.main import build_parser

    commands = build_parser().commands
    assert sorted(commands) == ["alerts", "bench", "camera", "dashboard", "demo", "detect",
                                "eval", "foxglove", "label", "router", "scene", "status",
                                "worker"]
    options = {name: {a.dest: a for a in p._actions} for name, p in commands.items()}
    assert options["eval"]["tie_break"].choices == list(TIE_BREAKS)
    assert options["eval"]["detectors"].default == list(DEFAULT_DETECTORS)
    assert all(family in options["eval"]["perturb"].help for family in FAMILIES)
    assert options["worker"]["model"].choices == options["detect"]["model"].choices == MODELS
    assert options["worker"]["threads"].default == available_cores()
    assert f"{FPS_RANGE[0]:g} to {FPS_RANGE[1]:g}" in options["scene"]["fps"].help
    # the types that check against the model's or the evaluation's tables, imported when called
    parser = build_parser()
    assert parser.parse_args(["eval", "--perturb", "jpeg50"]).perturb == "jpeg50"
    with pytest.raises(SystemExit):
        parser.parse_args(["detect", "in.mp4", "--perturb", "half-rate"])
    with pytest.raises(SystemExit):
        parser.parse_args(["camera", "--robot", "r", "--source", "x", "--fps", "1000"])


def test_the_package_names_what_it_imports_when_first_asked_for():
    # the model's names are imported on first use (PEP 562), and still listed and refused as
    # a module's: dir() shows them (editors, help()), an unknown name is an AttributeError
    # (hasattr, getattr with a default), not a KeyError
    import asnn

    assert set(asnn.__all__) <= set(dir(asnn))
    assert not hasattr(asnn, "no_such_name")
    from asnn.targets import Target

    assert asnn.Target is Target
    # its submodules too, as when the package imported them all (a review: ``asnn.model``
    # raised AttributeError once the package imported only the parameters)
    import asnn.model

    assert asnn.model is asnn.__getattr__("model") and asnn.retina.__name__ == "asnn.retina"
