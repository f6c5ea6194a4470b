"""The simulated U-CAT: vehicle, fin servos, fin hydrodynamics and sensors (pure stepping)."""
