"""visual_adaptive_servo: H. Wang's observer-based adaptive visual tracking (Automatica 2015).

ROS-free core: :mod:`.model` (robot + camera regressors), :mod:`.controller`
(the control law and the sampled controller), :mod:`.trajectory`,
:mod:`.config`, :mod:`.runner` (in-process closed loop) and :mod:`.cli` (``vas``).
The ROS 2 node is :mod:`.controller_node`.
"""

__version__ = "0.1.0"
