"""How the robot is drawn, the same in the console's 3-D view and in Foxglove's: colours (RGB)."""

HULL_COLOUR = (245, 196, 0)
NOSE_COLOUR = (200, 60, 40)
FIN_COLOUR = (40, 40, 40)
GHOST_COLOUR = (30, 144, 255)
