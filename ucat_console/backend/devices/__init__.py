"""Device drivers (one module per device) and the emulators that speak their bytes."""
