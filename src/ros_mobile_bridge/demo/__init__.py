"""The embedded demo robot: a simulated differential-drive robot behind a Foxglove server.

``rmb demo`` drives it; ``rmb demo --serve`` exposes it to other tools. Needs the ``demo`` extra
(``pip install 'ros-mobile-bridge[demo]'``) for the Foxglove SDK. See :class:`DemoRobot`.
"""

from ._robot import CMD_VEL_TIMEOUT_S, CMD_VEL_TOPICS, SERVICES, TOPICS, CmdVel, DemoRobot

__all__ = ["CMD_VEL_TIMEOUT_S", "CMD_VEL_TOPICS", "SERVICES", "TOPICS", "CmdVel", "DemoRobot"]
