"""What every detector returns for one frame."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .targets import Target

__all__ = ["Maps", "Response"]


@dataclass(frozen=True, slots=True)
class Maps:
    """Intermediate maps of one ASNN step, for figures and debugging (all (H, W) unless noted).

    Attributes
    ----------
    P : photoreceptor activation.
    R : (n_theta, H, W) motion energy per orientation theta_k = 2 pi k / n_theta.
    V : maximal motion energy over orientations.
    phi : estimated motion direction, radians, image coordinates.
    G : approach-sensitive map (after grouping, where the preset groups).
    M_a, M_d : bool attention masks.
    G_prime : G M_a M_d.
    """

    P: np.ndarray
    R: np.ndarray
    V: np.ndarray
    phi: np.ndarray
    G: np.ndarray
    M_a: np.ndarray
    M_d: np.ndarray
    G_prime: np.ndarray


@dataclass(frozen=True, slots=True)
class Response:
    """One frame's output of a detector.

    Attributes
    ----------
    index : int
        0-based number of the frame in the stream.
    u : float
        Membrane potential u(t) (paper eq. 26; for the LGMD models, their summed excitation).
    out : float
        Sigmoid output in [0.5, 1).
    spikes : int
        Spikes fired in this frame.
    spike_rate : float
        Spikes per second over the warning window.
    collision : bool
        The collision warning.
    targets : list of Target
        Looming regions (always empty for the LGMD models).
    maps : Maps or None
        Intermediate maps when the model was asked to record them.
    """

    index: int
    u: float
    out: float
    spikes: int
    spike_rate: float
    collision: bool
    targets: list[Target] = field(default_factory=list)
    maps: Maps | None = None

    @classmethod
    def silent(cls, index: int) -> "Response":
        """The response to a frame that only primes a stream (its first): u = 0, no spikes."""
        return cls(index=index, u=0.0, out=0.5, spikes=0, spike_rate=0.0, collision=False)

    def to_dict(self) -> dict:
        """JSON-ready fields (maps excluded)."""
        return {"u": self.u, "out": self.out, "spikes": self.spikes,
                "spike_rate": self.spike_rate, "collision": self.collision,
                "targets": [t.to_dict() for t in self.targets]}
