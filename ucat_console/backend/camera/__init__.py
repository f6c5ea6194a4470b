"""The vehicle's camera: its configuration, the emulated camera, real sources through PyAV
and the thread that publishes its frames on the telemetry stream (docs/camera.md)."""
