"""A benchmark case: which object, which concealed physics, which sensor and views.
The catalogue of cases lives in ``problems/``; :func:`generate.generate_case` makes the data."""

from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import ModelError, UnknownNameError
from .effects import ConcealedEffect
from .groundtruth import SIM_HZ, HandPlan
from .objects import GENERATORS
from .sensor import D435, SensorModel


@dataclass(frozen=True)
class Case:
    """One synthetic benchmark case.

    name: catalogue key.  category: object generator (see ``objects.GENERATORS``).  seed: object
    and noise seed.  effects: concealed effects in the ground truth only.  noise: sensor model.
    views: static calibrated cameras per time step (ignored with ``moving_camera``, which uses one
    camera orbiting over the episode).  frames: rendered time steps (spread evenly over the
    episode).  width, height [px], hfov_deg [deg]: camera.  plan: the hand.  record_hz: joint
    recording rate (divides the simulation rate).  expected: what a correct pipeline recovers.
    """

    name: str
    category: str
    seed: int
    effects: tuple[ConcealedEffect, ...] = ()
    noise: SensorModel = D435
    views: int = 8
    frames: int = 24
    width: int = 640
    height: int = 480
    hfov_deg: float = 69.0
    moving_camera: bool = False
    plan: HandPlan = field(default_factory=HandPlan)
    record_hz: int = 120
    expected: str = ""

    def __post_init__(self):
        if self.category not in GENERATORS:
            raise UnknownNameError(f"object category (case {self.name!r})", self.category, GENERATORS)
        if self.views < 1 or self.frames < 1 or self.width < 2 or self.height < 2:
            raise ModelError(f"case {self.name!r}: views, frames must be >= 1 and the image at least 2×2 px")
        if SIM_HZ % self.record_hz:
            raise ModelError(f"case {self.name!r}: record_hz={self.record_hz} must divide {SIM_HZ}")
        object.__setattr__(self, "effects", tuple(self.effects))
