"""Progress bars on stderr, silenced when the ``fourd`` logger is above INFO (``--quiet``)."""

from __future__ import annotations

import logging
from collections.abc import Iterable

from tqdm.auto import tqdm


def progress_enabled() -> bool:
    return logging.getLogger("fourd").isEnabledFor(logging.INFO)


def progress(iterable: Iterable | None = None, *, desc: str = "", total: int | None = None, unit: str = "frame"):
    """Wrap ``iterable`` in a tqdm bar on stderr unless progress is silenced."""
    return tqdm(
        iterable,
        desc=desc,
        total=total,
        unit=unit,
        disable=not progress_enabled(),
        leave=False,
        dynamic_ncols=True,
    )


def progress_write(text: str, file=None) -> None:
    """Write ``text`` and a newline to ``file`` (stderr) below the progress bars drawn there,
    not into the line of one."""
    tqdm.write(text, file=file)
