"""Human limits of the simulated user, each a parameter with its source.

The defaults are orders of magnitude reported in the motor-control literature, not
measurements of a particular person; ``sctd eval`` prints the profile it used.

- Reaction delay: a person acts on what they saw a moment ago; simple visual reaction
  times are about 0.2-0.25 s (Woods et al. 2015, "Factors influencing the latency of
  simple reaction time", Front. Hum. Neurosci. 9:131), and the human operator's
  effective delay in manual tracking is of the same order (McRuer & Jex 1967, "A review
  of quasi-linear pilot models", IEEE Trans. HFE 8(3)).
- Update period: manual control is intermittent, a few corrections per second (Craik
  1947, "Theory of the human operator in control systems", Br. J. Psychol. 38;
  Gawthrop, Loram, Lakie & Gollee 2011, "Intermittent control: a computational theory
  of human control", Biol. Cybern. 104).
- Input noise: motor noise grows with the size of the command (Harris & Wolpert 1998,
  "Signal-dependent noise determines motor planning", Nature 394), with a coefficient
  of variation of a few percent in steady force production (Jones, Hamilton & Wolpert
  2002, J. Neurophysiol. 88).
- Dead zone: deflections smaller than this are not made on purpose (tremor and the
  device's own dead band; assistive joysticks commonly have a 5-10 % dead band).
- Mode switch: releasing the stick, pressing the switch and checking the new mode.
  Herlant, Holladay & Srinivasa (2016, "Assistive teleoperation of robot arms via
  automatic time-optimal mode switching", HRI) measured mode switching at 17.4 % of
  execution time on a Kinova JACO; they give no single duration per switch, so the
  1 s default is our estimate, and ``sctd eval`` prints the share of the task time
  switching took to compare with their figure.
- Let-goes: a reaching movement is a sequence of sub-movements (Meyer, Abrams,
  Kornblum, Wright & Smith 1988, "Optimality in human motor performance: ideal control
  of rapid aimed movements", Psychol. Rev. 95(3)), and a person driving an arm through
  a joystick lets go between some of them to look and re-plan. ``step_pause`` lets go
  when a step of the task is reached; ``regrip_every`` also after that long of holding
  the stick in one step, for ``regrip_time``. Both are our assumptions, not
  measurements: they give a skill set's inference the moments at rest it needs to
  change the mapping, and the hesitant user's let-goes mid-reach are where a wrong
  engagement can happen.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class HumanProfile:
    """How a simulated person handles the input device (SI units; deflections as
    fractions of full scale)."""

    name: str
    reaction_delay: float = 0.2  # s between what happens and the user acting on it
    update_period: float = 0.15  # s between changes of the stick
    noise_constant: float = 0.02  # SD of additive noise on each axis
    noise_gain: float = 0.05  # SD per unit deflection (signal-dependent noise)
    dead_zone: float = 0.05  # smallest deflection made on purpose
    switch_time: float = 1.0  # s one mode switch costs
    # s the person lets go of the stick when a step of their task is reached, before
    # going on with the next (re-planning between sub-movements); 0: straight on
    step_pause: float = 0.0
    regrip_every: float = 0.0  # s of holding the stick after which the person lets go (0: never)
    regrip_time: float = 0.0  # s such a let-go lasts

    def describe(self) -> dict:
        return asdict(self)


PROFILES = {
    "steady": HumanProfile("steady"),
    "noisy": HumanProfile("noisy", reaction_delay=0.3, update_period=0.2, noise_constant=0.05,
                          noise_gain=0.15, dead_zone=0.1, switch_time=1.5),
    # steady, letting go of the stick for half a second at each step of the task
    "pausing": HumanProfile("pausing", step_pause=0.5),
    # pausing, and letting go for 0.3 s after every 1.5 s of holding the stick
    "hesitant": HumanProfile("hesitant", step_pause=0.5, regrip_every=1.5, regrip_time=0.3),
}
DEFAULT_PROFILE = "steady"


@dataclass(frozen=True)
class UserModel:
    """How the simulated person learns the device (:mod:`.device`), apart from their
    limits: ``lags``, the input-to-motion delays (s) they may come to expect; one
    delay of 0: every motion is paired with the stick held at the same moments."""

    name: str
    lags: tuple[float, ...]
    about: str

    def describe(self) -> dict:
        return asdict(self)


USER_MODELS = {
    "plain": UserModel("plain", (0.0,), "pairs each motion with the stick held at the same moments"),
    "adaptive": UserModel("adaptive", (0.0, 0.01, 0.02, 0.03, 0.04, 0.05),
                          "learns the input-to-motion delay (0-50 ms) with the device"),
}
DEFAULT_MODEL = "plain"
