"""The closed loop: body-frame PIDs, allocation, fin planners and executors, the robot I/O.

``ClosedLoop`` (closed_loop.py) runs under a ``SimulatedClock`` (headless) or a
``PacedClock`` (real time, planner threads); ``robot.interface.RobotIO`` is its only view of
the robot (``backend.sim_robot_io.SimRobotIO`` on the in-process simulator), and
``control.loop_core`` does its per-sample work.
"""
