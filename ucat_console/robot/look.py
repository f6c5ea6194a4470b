"""How the robot is drawn, the same in the console's 3-D view and in Foxglove's: colours (RGB)."""

HULL_COLOUR = (245, 196, 0)
NOSE_COLOUR = (200, 60, 40)
#: each fin's colour, by fin index: its blade in the 3-D views and its lines on the plots
FIN_COLOURS = ((214, 39, 40), (31, 119, 180), (44, 160, 44), (255, 127, 14))
GHOST_COLOUR = (30, 144, 255)


def hex_colour(rgb: tuple[int, int, int]) -> str:
    """``(214, 39, 40)`` -> ``"#d62728"``."""
    return "#{:02x}{:02x}{:02x}".format(*rgb)
