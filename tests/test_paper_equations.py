"""Each retina function names the paper's equation it implements, numbered as in the paper's
text (``../shared/paper/asnn-paper.tex``): the cited equation holds the function's symbol."""

from __future__ import annotations

import re

import pytest

from asnn import retina
from shared_data import SHARED

PAPER = SHARED / "paper" / "asnn-paper.tex"

# function -> a symbol that one of the equations its docstring cites must hold
SYMBOLS = {
    retina.photoreceptor: r"P(x,y,t)=I(x,y,t)",
    retina.dog_kernel: r"g_I(x,y",
    retina.bipolar: r"B_{+}^0(x,y,t)&=B_{+}(x,y,t)\otimes g_I",
    retina.temporal_filter_step: r"\tau \frac{\mathrm{d}z_n}{\mathrm{d}t}",
    retina.temporal_readout: r"\mathcal{L}(K,n,z_0)=K(z_n-z_{n+1})",
    retina.gabor_pair: r"g_{DS}(x,y)=",
    retina.center_surround_kernel: r"g_{CS}(x,y)=",
    retina._orientation_energy: r"E^{\theta}_{+}(x,y,t)&=",
    retina.motion_energy: r"R^{\theta}(x,y,t)=v_{+}",
    retina.motion_strength: r"V(x,y,t)=\max_{\theta}",
    retina.motion_direction: r"\hat{\varphi}(x,y,t) = \arctan2(R^{\frac{\pi}{2}}",
    retina.motion_components: r"V_x(x,y,t) &= V(x,y,t)\cos",
    retina.center_surround_inhibition: r"S^1_{+}(x,y,t)=relu",
    retina.approach_map: r"G(x,y,t)&=w^1_{+}G^1_{+}",
    retina.attention_blur: r"g_{\sigma}(x,y)=",
    retina.approach_attention: r"M_a(x,y,t)=",
    retina.direction_attention: r"M_d(x,y,t)=",
    retina.attended_response: r"G^{\prime}(x,y,t)=G(x,y,t)\cdot M_a(x,y,t)\cdot M_d",
    retina.membrane_potential: r"u(t)=\sum_{x,y} G^{\prime}",
    retina.sigmoid_output: r"out(t) =",
    retina.spike_count: r"spike(t) =",
    retina.spike_rate: r"\frac{1}{N_t\Delta t} \sum_{i-N_t}^t spike(t)",
    retina.collision_warning: r"Col(t)=",
}


def paper_equations(text: str) -> list[str]:
    """The numbered equations of the paper's body, in order (the appendix's derivation of the
    temporal filter's peak left out): one number per equation environment."""
    body = text.split("\\section{APPENDIX}")[0]
    return [" ".join(m.group(2).split()) for m in
            re.finditer(r"\\begin\{(equation|align)\}(.*?)\\end\{\1\}", body, re.S)]


def cited(doc: str) -> list[int]:
    """The equation numbers a docstring's first sentence cites: ``eq. 5``, ``eqs. 9, 14``,
    ``eqs. 12-14``."""
    first = doc.split("\n\n")[0]
    numbers = []
    for group in re.findall(r"eqs?\. ([0-9][0-9 ,\-]*)", first):
        for part in group.replace(" ", "").strip(",").split(","):
            low, _, high = part.partition("-")
            numbers += range(int(low), int(high or low) + 1)
    return numbers


@pytest.mark.skipif(not PAPER.is_file(), reason="../shared/paper is absent")
def test_every_retina_stage_cites_the_equation_that_holds_its_symbol():
    equations = paper_equations(PAPER.read_text(encoding="utf-8"))
    assert len(equations) == 34  # the body's: 1-31 the retina and targets, 32-34 the output
    wrong = {}
    for function, symbol in SYMBOLS.items():
        numbers = cited(function.__doc__)
        assert numbers, f"{function.__name__} cites no equation"
        if not any(symbol in equations[n - 1] for n in numbers if 0 < n <= len(equations)):
            wrong[function.__name__] = numbers
    assert not wrong, f"cited equations without the stage's symbol: {wrong}"


# kernel symbol in a docstring -> the text of the equation that defines it
KERNELS = {"g_I": r"g_I(x,y", "g_DS": r"g_{DS}(x,y)=", "g_CS": r"g_{CS}(x,y)=",
           "g_sigma": r"g_{\sigma}(x,y)="}


@pytest.mark.skipif(not PAPER.is_file(), reason="../shared/paper is absent")
def test_a_kernel_cited_with_an_equation_cites_the_one_that_defines_it():
    """Beyond the first sentences: a docstring line that describes a kernel (a parameter's
    description that starts with its symbol: ``g_CS, the ... kernel (eq. 11)``) and cites an
    equation cites the kernel's definition."""
    import inspect

    equations = paper_equations(PAPER.read_text(encoding="utf-8"))
    wrong = []
    for name, function in inspect.getmembers(retina, inspect.isfunction):
        for line in (function.__doc__ or "").splitlines():
            for symbol, definition in KERNELS.items():
                if not re.match(rf"\s*{symbol}\b", line):
                    continue
                numbers = cited(line)
                if numbers and not any(definition in equations[n - 1] for n in numbers
                                       if 0 < n <= len(equations)):
                    wrong.append(f"{name}: {line.strip()}")
    assert not wrong, "kernels cited with an equation that does not define them:\n" + \
        "\n".join(wrong)


# the body's equations that are not the model's: eq. 8 is the traditional temporal kernel
# (Adelson and Bergen's) the paper compares its filter with
NOT_THE_MODEL = {8}


@pytest.mark.skipif(not PAPER.is_file(), reason="../shared/paper is absent")
def test_every_equation_of_the_model_is_named_by_a_function():
    """CONTRIBUTING, "One place each": a reader holding the code beside the paper finds each of
    its equations named in the first paragraph of a docstring in ``asnn/retina.py`` (or, for
    the targets' population-coded motion, ``asnn/targets.py``)."""
    import inspect

    from asnn import targets

    count = len(paper_equations(PAPER.read_text(encoding="utf-8")))
    named = set()
    for module in (retina, targets):
        for _, function in inspect.getmembers(module, inspect.isfunction):
            if function.__module__ == module.__name__:
                named.update(cited(function.__doc__ or ""))
    missing = sorted(set(range(1, count + 1)) - NOT_THE_MODEL - named)
    assert not missing, f"equations no function's docstring names: {missing}"
