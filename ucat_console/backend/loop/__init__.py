"""The closed loop: body-frame PIDs, allocation, fin planners and executors, the robot I/O.

``ClosedLoop`` (closed_loop.py) runs under a ``SimulatedClock`` (headless) or a
``PacedClock`` (real time, planner threads); ``RobotIO`` (robot_io.py) is its only view of
the robot, with ``SimRobotIO`` on the in-process simulator.
"""
