"""Where per-frame stages run: in this process, in local processes, or on a Dask cluster.

A per-frame stage is a pure function of one frame and the options (DESIGN.md, "Growing past one
machine"), so it can be mapped over the frames by any executor. :func:`map_frames` is that map,
one code path for three schedulers:

- ``"sync"``: one frame after the other in this process (the default; what every method did);
- ``"processes"``: Dask's local multiprocessing scheduler, one worker process per core (or
  ``workers``);
- an address (``"tcp://HOST:PORT"`` or ``"HOST:PORT"``): the workers of a running
  ``dask.distributed`` scheduler (``dask scheduler`` and ``dask worker ADDRESS`` on the
  machines; the frames and the function travel to them by pickle, the results come back).

The results are the same whichever runs them (the function is deterministic), in the frames'
order. Dask is imported only when a scheduler other than ``"sync"`` is asked for.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence

from fourd.errors import InputError
from fourd.progress import progress

__all__ = ["SCHEDULERS", "check_scheduler", "map_frames"]

#: The named schedulers; anything else must be a scheduler's address.
SCHEDULERS = ("sync", "processes")

_ADDRESS = re.compile(r"^(tcp|tls|inproc|ucx)://\S+$|^[A-Za-z0-9_.\-\[\]:]+:\d+$")


def check_scheduler(scheduler: str) -> str:
    """``scheduler`` when it is ``"sync"``, ``"processes"`` or a scheduler address; else an
    :class:`InputError` saying what is accepted.

    >>> check_scheduler("processes"), check_scheduler("127.0.0.1:8786")
    ('processes', '127.0.0.1:8786')
    """
    text = str(scheduler).strip()
    if text in SCHEDULERS or _ADDRESS.match(text):
        return text
    raise InputError(
        f"scheduler {scheduler!r}: expected sync, processes or a dask.distributed scheduler's "
        "address (tcp://HOST:PORT)"
    )


def _dask():
    try:
        import dask
    except ImportError:  # pragma: no cover - dask is a dependency; a trimmed install may lack it
        raise InputError("this scheduler needs Dask: pip install 'dask[distributed]'") from None
    return dask


def map_frames(
    function: Callable,
    items: Sequence,
    *,
    scheduler: str = "sync",
    workers: int | None = None,
    desc: str = "frames",
) -> list:
    """``[function(item) for item in items]``, run by ``scheduler`` (module docstring).

    ``function`` must be picklable for the other schedulers (a module-level function or a
    :func:`functools.partial` of one); ``workers`` caps the local processes (``"processes"``).
    """
    scheduler = check_scheduler(scheduler)
    items = list(items)
    if scheduler == "sync" or not items:
        return [function(item) for item in progress(items, desc=desc, total=len(items))]
    if scheduler == "processes":
        dask = _dask()
        tasks = [dask.delayed(function)(item) for item in items]
        return list(dask.compute(*tasks, scheduler="processes", num_workers=workers))
    _dask()
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover
        raise InputError("a scheduler address needs dask.distributed: pip install 'dask[distributed]'") from None
    address = scheduler if "://" in scheduler else f"tcp://{scheduler}"
    try:
        client = Client(address, timeout="5s", set_as_default=False)
    except OSError as error:
        raise InputError(f"scheduler {scheduler}: cannot connect ({error})") from None
    try:
        # the frames go to the workers as data of their own, not inside the task graph
        futures = client.map(function, client.scatter(items), pure=False)
        return client.gather(futures)
    finally:
        client.close()
