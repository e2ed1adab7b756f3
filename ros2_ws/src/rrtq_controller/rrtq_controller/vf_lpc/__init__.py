"""VF-LPC control level (pure numpy/scipy).

Koopman/EDMD model, online sparse GP, receding-horizon actor-critic with an exponential
barrier. See docs/vf_lpc.md.
"""

from .config import LPCConfig
from .controller import VFLPCController, default_gp_config
from .koopman import LIFTINGS, KoopmanModel, Lifting, fit_edmd, prediction_errors
from .lpc import HorizonSolution, RecedingHorizonActorCritic
from .sparse_gp import OnlineSparseGP, SparseGPConfig

__all__ = ['HorizonSolution', 'KoopmanModel', 'LIFTINGS', 'LPCConfig', 'Lifting',
           'OnlineSparseGP', 'RecedingHorizonActorCritic', 'SparseGPConfig',
           'VFLPCController', 'default_gp_config', 'fit_edmd', 'prediction_errors']
