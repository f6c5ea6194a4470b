"""The Review tab's Trends folder: a figure of the runs the current search finds, by day or by a
recorded MPC weight, drawn as uPlot charts like the page's other plots.

The choices are two dropdowns, Figure (``backend.review.trend.FIGURES``: energy per metre, cost
of transport, the tracking errors, strokes in the St corridor) and Against (the day, or
``loop.mpc.lam_*`` of the run's recorded configuration). Each run is a dot, the ends of its
interval (energy per metre and cost of transport, when the library has one) small grey dots
above and below it, and its group's mean (its day, or the weight's value) a line. Against the
day the x axis is a time axis (uPlot's), against a weight a number axis: two charts, the one in
use shown (a chart's scales are fixed when it is made).

Every choice a page sends is checked on the server (:meth:`ReviewSession.trend
<ucat_console.backend.review.session.ReviewSession.trend>`, and again by the supervisor's run
library): an unknown figure or axis is refused with a message naming it and the choices, the
dropdowns show the choice in force again and the chart stays as it was. The chart is drawn again
after each search (the runs found changed) once the folder has drawn one.
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from ucat_console.backend.review import trend as trends
from ucat_console.backend.sessions.library_query import FIELDS
from ucat_console.ui.markdown import esc
from ucat_console.ui.plots import _empty, _series
from ucat_console.ui.viser_compat import set_plot_data

_DOT = {"label": "a run", "stroke": "#1f77b4", "width": 0, "points": {"show": True, "size": 7,
                                                                      "stroke": "#1f77b4", "fill": "#1f77b4"}}
_END = {"stroke": "#999", "width": 0, "points": {"show": True, "size": 4, "stroke": "#777", "fill": "#777"}}
_MEAN = _series("mean of its group", "#ff7f0e", 1.5)
SERIES_COUNT = 5  # x, value, low end, high end, mean


def _series_for(unit_label: str) -> tuple[dict, ...]:
    return ({"label": unit_label}, _DOT, {**_END, "label": "interval low"}, {**_END, "label": "interval high"}, _MEAN)


class TrendPanel:
    """The Trends folder (module docstring); ``job(what, fn, coalesce, value=...)`` and
    ``allow`` as the run list's."""

    def __init__(self, gui: Any, review: Any, *, job: Callable[..., Callable[[Any], None]],
                 allow: Callable[..., None] | None = None, height: int = 200) -> None:
        self.review = review  # the ReviewSession
        self.chosen: tuple[str, str] = ("epm", trends.DATE)  # the field and axis in force
        self.drawn = False  # a chart was drawn: searches draw it again
        self.points: list[Any] = []
        with gui.add_folder("Trends", order=0.6, expand_by_default=False):
            self.figure = gui.add_dropdown("Figure", tuple(trends.FIGURES.values()),
                                           initial_value=trends.FIGURES["epm"],
                                           hint="a figure of each run the search finds")
            self.axis = gui.add_dropdown("Against", trends.AXES, initial_value=trends.DATE,
                                         hint="the day it ran, or a recorded MPC weight")
            self.draw_button = gui.add_button("Draw trend", hint="the runs the search finds")
            self.about = gui.add_markdown("Choose a figure and Draw trend.")
            common = dict(legend={"show": True, "live": False}, height=height, cursor={"sync": {"key": "trend"}})
            self.by_date = gui.add_uplot(
                _empty(SERIES_COUNT), _series_for("start"), title="by date",
                scales={"x": {"time": True}}, axes=({"label": "start"}, {"size": 50}), **common)
            self.by_value = gui.add_uplot(
                _empty(SERIES_COUNT), _series_for("value"), title="by weight",
                scales={"x": {"time": False}}, axes=({"label": "weight"}, {"size": 50}), visible=False, **common)
        choice = lambda: (self.figure.value, self.axis.value)  # noqa: E731: the values the page sent
        for h in (self.figure, self.axis):
            h.on_update(job("Trend", lambda v: self.draw(*v), True, value=choice))
        self.draw_button.on_click(job("Trend", lambda v: self.draw(*v), True, value=choice))
        if allow is not None:
            for h in (self.figure, self.axis, self.draw_button):
                allow(h, False)

    def handles(self) -> tuple[Any, ...]:
        return (self.figure, self.axis, self.draw_button)

    def _show_chosen(self) -> None:
        figure, axis = trends.FIGURES[self.chosen[0]], self.chosen[1]
        if self.figure.value != figure:
            self.figure.value = figure
        if self.axis.value != axis:
            self.axis.value = axis

    def draw(self, figure: object = None, by: object = None) -> int:
        """Draw ``figure`` against ``by`` (None: the choice in force) for the runs the search
        finds; the runs drawn. Refused (ValueError): the choice in force is shown again and
        the chart stays."""
        f = trends.FIGURES[self.chosen[0]] if figure is None else figure
        b = self.chosen[1] if by is None else by
        try:
            name, axis, points = self.review.trend(f, b)
        except ValueError:
            self._show_chosen()
            raise
        self.chosen = (name, axis)
        self.points = points
        self._show_chosen()
        c = trends.chart(points, axis)
        field = FIELDS[name]
        unit = f" ({field.unit})" if field.unit else ""
        chart, other = (self.by_date, self.by_value) if axis == trends.DATE else (self.by_value, self.by_date)
        if len(c.x) >= 1:
            x = c.x if len(c.x) > 1 else np.array([c.x[0], c.x[0] + 1.0])  # a chart needs an x range
            ys = [c.value, c.lo, c.hi, c.mean]
            if len(c.x) == 1:
                ys = [np.repeat(y, 2) for y in ys]
                for y in ys:
                    y[1] = np.nan
            set_plot_data(chart, (x, *ys))
        else:
            set_plot_data(chart, _empty(SERIES_COUNT))
        chart.title = f"{trends.FIGURES[name]} by {'date' if axis == trends.DATE else axis}"
        chart.axes = ({"label": "start" if axis == trends.DATE else axis}, {"label": f"{name}{unit}", "size": 50})
        chart.visible, other.visible = True, False
        query = self.review.query[0]
        found = f"the runs matching {esc(query)}" if query.strip() else "every run"
        parts = [f"{len(c.x)} run{'s' if len(c.x) != 1 else ''} of {found} with {esc(trends.FIGURES[name])}"
                 + (f", in {c.groups} group{'s' if c.groups != 1 else ''}" if axis != trends.DATE else "")]
        if c.left_out:
            parts.append(f"{c.left_out} left out (no {'start' if axis == trends.DATE else esc(axis)} to place "
                         "them by)")
        parts.append("interval ends grey" if c.has_interval else "no interval for this figure")
        self.about.content = "; ".join(parts) + "."
        self.drawn = True
        return len(c.x)

    def found(self) -> None:
        """The search found another list: draw it again (when the folder has drawn one)."""
        if self.drawn:
            try:
                self.draw()
            except ValueError as e:  # the library refused: say so, the list stands
                self.about.content = esc(str(e))
