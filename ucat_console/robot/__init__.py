"""The robot's description: what every layer agrees on about the U-CAT.

Fin count, order and signs (:mod:`.fins`), hull and fin geometry (:mod:`.geometry`), the
sensor reading types (:mod:`.readings`), units and their conversions (:mod:`.units`),
quaternions, rotation matrices and Euler angles (:mod:`.rotations`), the fin drive's motion
(:mod:`.servo`), the loop's view of a robot (:mod:`.interface`), and the vocabulary that
describes a message field's meaning, unit and frame (:mod:`.fields`, which the readings and
the telemetry messages annotate their fields with). This package imports nothing else of ``ucat_console``
(checked by import-linter), so the core, the telemetry, the plant, the drivers and the page
all import it without importing each other.
"""
