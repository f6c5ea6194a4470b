"""ucat-console: operator console and onboard controller for the four-fin U-CAT robot."""

from ucat_console.compiled_cache import use_source_keyed_cache as _use_source_keyed_cache

__version__ = "0.1.0"

# before any kernel is defined: numba's cache keyed by the compiled sources (compiled_cache)
_use_source_keyed_cache()
