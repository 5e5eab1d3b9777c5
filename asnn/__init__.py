"""ASNN: the Approach-Sensitive Neural Network for collision detection (numerical core, no I/O).

The parameters are imported with the package; the model and its results (numba, OpenCV) when
first named (``asnn.ASNN``, ``from asnn import ASNN``), so that a process that reads a preset's
name but runs no model (``asnn router``, ``asnn status``, the command line's parser) loads
neither.
"""

from .params import ASNNParams, preset, preset_names

__all__ = ["ASNN", "ASNNParams", "FrameError", "Maps", "Response", "Target", "TimingWarning",
           "TrackReport", "preset", "preset_names"]
__version__ = "0.1.0"

# the names above imported from their module when first asked for (PEP 562)
_MODULE_OF = {"ASNN": "model", "FrameError": "errors", "Maps": "response", "Response": "response",
              "TimingWarning": "errors", "TrackReport": "response", "Target": "targets"}


def __getattr__(name: str):
    import importlib
    import importlib.util

    if name in _MODULE_OF:
        value = getattr(importlib.import_module(f".{_MODULE_OF[name]}", __name__), name)
    elif importlib.util.find_spec(f"{__name__}.{name}") is not None:
        # a submodule (``import asnn; asnn.model.ASNN``), as when the package imported them all
        value = importlib.import_module(f".{name}", __name__)
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    globals()[name] = value  # asked once
    return value


def __dir__():
    return sorted(set(globals()) | set(_MODULE_OF))
