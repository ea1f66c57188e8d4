"""Progress bars: tqdm on a terminal, quiet when stderr is not a TTY or when CI is set."""

from __future__ import annotations

import os
import sys


def progress(iterable=None, total=None, desc: str = "", **kw):
    """A tqdm progress bar on a terminal; silent when stderr is not a TTY or CI is set."""
    if "ipykernel" in sys.modules:  # a notebook: tqdm's widget bar
        from tqdm.auto import tqdm  # noqa: PLC0415 - start-up: tqdm.auto (~0.2 s)
    else:  # tqdm.auto also imports asyncio (for async iteration, unused here): ~0.03 s more
        from tqdm.std import tqdm  # noqa: PLC0415 - start-up: tqdm

    disable = (not sys.stderr.isatty()) or bool(os.environ.get("CI"))
    return tqdm(iterable, total=total, desc=desc, disable=disable, leave=False, **kw)
