"""Setting the live view's often-changing viser properties without viser's per-assignment work.

Every assignment to a viser handle's property (``handle.data = ...``, ``node.position =
...``) casts the value against the property's type hint (for a tuple of arrays, each array
is compared with four ``numpy.typing`` aliases and copied), compares it with the last value
(``numpy.allclose`` for a pose), then queues the update. The live view sets the plots' data
12 times a second and the robot's pose 40 times a second with values that are new every
time, built here as the arrays the page takes: in profiles of the console with two pages,
that casting and comparing was half of the live view's CPU. These two functions store the
value where viser keeps it and queue the same message as the assignment would, and nothing
else. They use viser's handle internals (``_impl``, ``_queue_update``,
``_queue_scene_message``), as the page guard does; checked against viser 1.1.1, the
version ``constraints.txt`` pins (``tests/ui/test_scene.py`` and ``test_plots.py`` check
what the pages receive).

The caller must not change a value after handing it over (viser serialises it later, in
its own thread): the live view builds new arrays for every update.
"""

from __future__ import annotations

from typing import Any

import viser._messages as vm


def set_prop(handle: Any, name: str, value: Any) -> None:
    """``handle.<name> = value`` for a value the page takes as it is (arrays of float64
    or float32 for a plot's data, float32 for batched orientations), without the cast and
    the comparison."""
    setattr(handle._impl.props, name, value)
    handle._queue_update(name, value)


def set_pose(node: Any, position: tuple[float, float, float], wxyz: tuple[float, float, float, float]) -> None:
    """``node.position = position; node.wxyz = wxyz`` (tuples of floats), without the
    casts and the comparisons with the last pose."""
    impl = node._impl
    impl.position[:] = position
    impl.wxyz[:] = wxyz
    queue = impl.api._queue_scene_message
    queue(vm.SetPositionMessage(impl.name, position))
    queue(vm.SetOrientationMessage(impl.name, wxyz))
