"""ucat-console: operator console and onboard controller for the four-fin U-CAT robot."""

__version__ = "0.1.0"
