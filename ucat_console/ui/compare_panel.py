"""Runs side by side in the page: two to four sessions, or the segments of one, overlaid, with
their Table V figures and the not-comparable flags; downloads of the table (Markdown, CSV)
and the overlay (PNG) (docs/review.md).

Every value the page sends is checked here: each chosen session must be one of the listing's
(a plain session id), the cutting and aligning codes ones of
:data:`~ucat_console.backend.review.compare.SEGMENT_CODES`. Reading the sessions runs on the
console's page jobs (rationed per page, like opening a session) and a session of more than
:data:`MAX_MESSAGES` messages is refused (the shell's ``sessions compare`` has no such limit).
"""

from __future__ import annotations

import io
import logging
import time
from typing import Any, Callable, Sequence

import numpy as np

from ucat_console.backend.review import compare, export
from ucat_console.backend.review.metrics import LABELS, MECHANICAL, MetricsConfig, TableRow
from ucat_console.backend.sessions.limits import MemoryBudget
from ucat_console.ui.markdown import esc, within

log = logging.getLogger(__name__)

#: how many runs the page compares at most
MAX_RUNS = 4
#: the largest session the page compares (messages)
MAX_MESSAGES = 3_000_000
NONE = "(none)"
SEGMENT_CHOICES = (NONE, *compare.SEGMENT_CODES)
ALIGN_CHOICES = ("start", *compare.SEGMENT_CODES)
#: the page's table: these figures (the downloads have every one)
PAGE_COLUMNS = ("power", "energy_per_metre", "cost_of_transport", "speed_mae", "st_mae", "st_in")


def page_table(rows: Sequence[TableRow], about: Sequence[str] = ()) -> str:
    """The table in Markdown, after a line saying which power its P, J/m and CoT are of: a row
    per figure and a column per run (``#1`` ... named in a list above it, each with ``about``
    it: its modes and MPC weights), so that it fits the docked panel however long the runs'
    names are."""
    heads = ("P (W)", "J/m", "CoT", "speed MAE", "St MAE", "St in %")
    source = rows[0].source_label if rows else "–"
    out = [esc(f"Power: {source}. The downloads have the {LABELS[MECHANICAL]} figures too."), ""]
    for k, r in enumerate(rows):
        flag = f" **not comparable**: {esc(r.not_comparable)}" if r.not_comparable else ""
        what = f" ({esc(about[k])})" if k < len(about) and about[k] else ""
        out.append(f"- #{k + 1}: {esc(r.label)}{what}{flag}")
    out += ["", "| | " + " | ".join(f"#{k + 1}" for k in range(len(rows))) + " |", "|---" * (len(rows) + 1) + "|"]
    for head, key in zip(heads, PAGE_COLUMNS):
        out.append(f"| {head} | " + " | ".join(esc(export.cell(r, key)) for r in rows) + " |")
    return "\n".join(out)


def download_name(names: Sequence[str], segments: str) -> str:
    """The downloads' file name (without its suffix): the runs compared, and where they were cut."""
    cut = "" if segments == NONE else f"-at-{segments}"
    return "compare-" + "-vs-".join(names) + cut


def _image(png: bytes) -> np.ndarray:
    import matplotlib.image as mpimg

    return (mpimg.imread(io.BytesIO(png), format="png")[:, :, :3] * 255).astype(np.uint8)


class ComparePanel:
    """One page's comparison of runs (module docstring)."""

    def __init__(self, gui: Any, container: Any, directory: Any, *, cfg: MetricsConfig,
                 sessions: Callable[[], list[Any]],
                 jobs: Callable[[str, Callable[[], Any], bool], str | None] | None = None,
                 allow: Callable[..., None] | None = None, client: Any = None,
                 present: Callable[[], bool] = lambda: True, budget: MemoryBudget | None = None,
                 describe: Callable[[str], str] = lambda name: "") -> None:
        """``present()``: whether the page is still connected (a job that ends after its page
        went ends quietly: its elements have gone with the page); ``budget``: the console's
        memory budget for reading session files (default: the panel's own); ``describe(id)``:
        what the table says of a run beside its name (the console: its modes and MPC weights
        from the run library)."""
        self.describe = describe
        self.gui = gui
        self.present = present
        self.directory = directory
        self.budget = budget if budget is not None else MemoryBudget()
        self.cfg = cfg
        self._sessions = sessions
        self.jobs = jobs
        self.client = client
        self.result: tuple[list[TableRow], list[compare.Window]] | None = None
        self._downloads: dict[str, tuple[str, bytes]] = {}
        with within(container):
            with gui.add_folder("Compare runs", order=4.0, expand_by_default=False):
                self.runs = [gui.add_dropdown(f"Run {k + 1}", (NONE,), initial_value=NONE) for k in range(MAX_RUNS)]
                self.segments = gui.add_dropdown("Segments at", SEGMENT_CHOICES, initial_value=NONE,
                                                 hint="cut each run at these events (one run needs this)")
                self.align = gui.add_dropdown("Align at", ALIGN_CHOICES, initial_value="start",
                                              hint="overlay each run or segment from its first event of this kind")
                self.refresh_button = gui.add_button("Refresh sessions")
                self.compare_button = gui.add_button("Compare", color="blue")
                self.message = gui.add_markdown("")
                self.table = gui.add_markdown("")
                self.image = gui.add_image(np.zeros((4, 4, 3), dtype=np.uint8), visible=False)
                self.download = {k: gui.add_button(f"Download {k}", disabled=True) for k in ("Markdown", "CSV", "PNG")}
        self.refresh_button.on_click(self._job("Refresh sessions", self.refresh))
        self.compare_button.on_click(self._job("Compare", self.run_from_page))
        for kind, button in self.download.items():
            button.on_click(lambda event, k=kind: self._send(event, k))
        if allow is not None:
            for h in (*self.runs, self.segments, self.align, self.refresh_button, self.compare_button,
                      *self.download.values()):
                allow(h, False)
        if jobs is None:
            self.refresh()
        else:  # the listing is read on the page jobs' worker, as the Review tab's
            jobs("Refresh sessions", lambda: self.act(self.refresh), True)

    # ------------------------------------------------------------------ page actions
    def _job(self, what: str, fn: Callable[[], Any]) -> Callable[[Any], None]:
        def cb(event: Any) -> None:
            if getattr(event, "client", None) is None and getattr(event, "client_id", None) is None:
                return  # a value set from code
            if self.jobs is None:
                self.act(fn)
                return
            why = self.jobs(what, lambda: self.act(fn), False)
            if why is not None:
                self.act(lambda: self.show(why, error=True))
        return cb

    def act(self, fn: Callable[[], Any]) -> bool:
        """Run one action; a refusal is shown. When the page has gone meanwhile, nothing is
        shown and nothing is an error."""
        try:
            try:
                fn()
                return True
            except (ValueError, OSError, RuntimeError) as e:
                if not self.present():
                    raise
                self.show(str(e), error=True)
            except Exception as e:  # a bug must not pass silently
                if not self.present():
                    raise
                log.exception("comparing runs failed")
                self.show(f"internal error: {e}", error=True)
        except Exception:
            if self.present():
                raise
            log.debug("a page left during a comparison", exc_info=True)
        return False

    def show(self, text: str, error: bool = False) -> None:
        self.message.content = time.strftime("%H:%M:%S ") + ("**Refused:** " if error else "") + esc(text)

    def refresh(self) -> None:
        names = (NONE, *(s.session_id for s in self._sessions()))
        for d in self.runs:
            current = d.value
            d.options = names
            d.value = current if current in names else NONE

    def run_from_page(self) -> None:
        self.run([d.value for d in self.runs], self.segments.value, self.align.value)

    def run(self, chosen: Sequence[object], segments: object, align: object) -> list[TableRow]:
        """Compare the chosen sessions (checked against the listing) and show the result."""
        known = {s.session_id for s in self._sessions()}
        names = []
        for k, name in enumerate(chosen):
            if name == NONE:
                continue
            if not isinstance(name, str) or name not in known:
                raise ValueError(f"run {k + 1}: {str(name)[:80]!r} is not a session in {self.directory}")
            names.append(name)
        if segments not in SEGMENT_CHOICES:
            raise ValueError(f"segments: {str(segments)[:40]!r} is not one of {', '.join(SEGMENT_CHOICES)}")
        if align not in ALIGN_CHOICES:
            raise ValueError(f"align: {str(align)[:40]!r} is not one of {', '.join(ALIGN_CHOICES)}")
        if not names:
            raise ValueError("choose the sessions to compare (Run 1 ... Run 4)")
        if len(names) == 1 and segments == NONE:
            raise ValueError("one session: choose where to cut it into segments (Segments at)")
        codes = () if segments == NONE else (str(segments),)
        wins: list[compare.Window] = []
        for name in names:
            run = compare.load_run(name, self.directory, max_messages=MAX_MESSAGES, budget=self.budget)
            wins += compare.windows(run, codes, None if align == "start" else str(align))
        rows = compare.table(wins, self.cfg)
        png = export.png_bytes(wins, dpi=60)
        self.result = (rows, wins)
        name = download_name(names, str(segments))
        self._downloads = {
            "Markdown": (f"{name}.md", export.markdown(rows, wins, self.cfg).encode()),
            "CSV": (f"{name}.csv", export.csv_text(rows, wins).encode()),
            "PNG": (f"{name}.png", png),
        }
        about = []
        for w in wins:
            try:
                about.append(self.describe(w.run.name))
            except ValueError:  # not in the library (yet): the run is shown by its name alone
                about.append("")
        self.table.content = page_table(rows, about)
        self.image.image = _image(png)
        self.image.visible = True
        for b in self.download.values():
            b.disabled = False
        self.show(f"compared {len(rows)} run{'s' if len(rows) > 1 else ''} or segments "
                  f"({self.cfg.confidence * 100:g}% intervals over cycles)")
        return rows

    def _send(self, event: Any, kind: str) -> None:
        client = getattr(event, "client", None)
        got = self._downloads.get(kind)
        if client is None or got is None:
            return
        try:
            client.send_file_download(*got)
        except Exception:
            log.debug("a download was not sent", exc_info=True)
