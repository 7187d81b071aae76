"""Controllers as DCS function blocks: the PI and the stiction compensators.

Every controller answers the same block interface (:class:`FunctionBlock`)::

    from valve_gym.agents import load_controller
    ctrl = load_controller("knocker", S=0.03)   # settings checked, defaults by the paper's rule
    ctrl.reset(sp, pv, op)                       # bumpless start (m, m, 0..1)
    op = ctrl.step(sp, pv)                       # one scan of ctrl.scan_s seconds

=============================  ================================================
``"pi"``                       :class:`PIBlock` (SIMC default tuning, ``detune``)
``"knocker"``                  :class:`Knocker` (Hägglund 2002)
``"constant_reinforcement"``   :class:`ConstantReinforcement` (Ivan & Lakshminarayanan 2009)
``"two_move"``                 :class:`TwoMove` (Srinivasan & Rengaswamy 2005, 2008)
``"integral_freeze"``          :class:`IntegralFreeze` (dead zone in the integral)
``"learned"``                  :func:`valve_gym.agents.adaptive.load_adaptive` (trained over a family of plants)
``"learned_network"``          ``valve_gym.agents.learned.load_learned`` (loaded on first use)
=============================  ================================================
"""
from .block import FunctionBlock, Setting
from .constant_reinforcement import ConstantReinforcement
from .integral_freeze import IntegralFreeze
from .knocker import Knocker
from .pi import PIBlock
from .registry import ControllerLoadError, available_controllers, load_controller
from .two_move import TwoMove

__all__ = ["FunctionBlock", "Setting", "PIBlock", "Knocker", "ConstantReinforcement", "TwoMove",
           "IntegralFreeze", "load_controller", "available_controllers", "ControllerLoadError"]
