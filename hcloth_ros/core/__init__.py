"""The ROS-free engine: model, state, control, solvers and their numba kernels."""

from hcloth_ros.core.control import Control
from hcloth_ros.core.model import ClothBuilder, ClothModel, Placement
from hcloth_ros.core.scene import make_scene, Scene
from hcloth_ros.core.solvers import make_solver, SOLVERS, StepReport
from hcloth_ros.core.state import State
from hcloth_ros.core.warmup import kernels_cached, warm_up

__all__ = ['ClothBuilder', 'ClothModel', 'Control', 'Placement', 'SOLVERS', 'Scene',
           'State', 'StepReport', 'kernels_cached', 'make_scene', 'make_solver', 'warm_up']
