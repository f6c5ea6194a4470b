"""The closed loop: body-frame PIDs, allocation, fin planners and executors, the robot I/O.

``ClosedLoop`` (closed_loop.py: the run loop) runs under a ``SimulatedClock`` (headless) or a
``PacedClock`` (real time, planner threads), from its parts: ``commands`` (what the
supervisor and the page ask), ``actuators`` (the fins' executors, planners and plan
hand-over), ``outbox`` (the telemetry out), ``modes`` (the registry of fin controllers) and
``planners``. ``robot.interface.RobotIO`` is its only view of the robot
(``backend.sim_robot_io.SimRobotIO`` on the in-process simulator), and ``control.loop_core``
does its per-sample work. docs/architecture.md describes the whole.
"""
