"""Kept for old imports, and one name for every shipped controller (agent side):
the scenes' hand-written controllers of :mod:`remoteenv.scene_controllers` and
the delay-aware CartPole predictors of :mod:`remoteenv.latency.predictors`."""

from remoteenv.latency.predictors import CartpoleExpectedPredictor, CartpoleHoldPredictor, CartpolePredictor
from remoteenv.scene_controllers.cartpole import (
    CARTPOLE_DT,
    CARTPOLE_GAINS,
    CARTPOLE_OBS,
    CARTPOLE_SOFT_GAINS,
    cartpole_continuous,
    cartpole_discrete,
    cartpole_model_path,
)
from remoteenv.scene_controllers.hexapod import (
    HEXAPOD_PHASE,
    HEXAPOD_QUAT,
    HEXAPOD_SIDE,
    hexapod_heading,
    hexapod_tripod,
)
from remoteenv.scene_controllers.reacher import REACHER_LINKS, reacher_reach

__all__ = [
    "CARTPOLE_DT",
    "CARTPOLE_GAINS",
    "CARTPOLE_OBS",
    "CARTPOLE_SOFT_GAINS",
    "HEXAPOD_PHASE",
    "HEXAPOD_QUAT",
    "HEXAPOD_SIDE",
    "REACHER_LINKS",
    "CartpoleExpectedPredictor",
    "CartpoleHoldPredictor",
    "CartpolePredictor",
    "cartpole_continuous",
    "cartpole_discrete",
    "cartpole_model_path",
    "hexapod_heading",
    "hexapod_tripod",
    "reacher_reach",
]
