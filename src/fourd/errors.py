"""Errors a user can act on.

Every problem with the user's input is raised as :class:`InputError`, whose message names the
file (when there is one) and the problem in one line. The command line turns it into exit
status 2 with that line on stderr, never a traceback.
"""

from __future__ import annotations

import os


class InputError(ValueError):
    """Bad input: a file, a folder, an option or an array the user gave us.

    Parameters
    ----------
    problem : str
        What is wrong, in words a user understands.
    path : str or os.PathLike, optional
        The file or folder concerned; prefixed to the message.
    """

    def __init__(self, problem: str, path: str | os.PathLike | None = None):
        self.problem = problem
        self.path = None if path is None else os.fspath(path)
        super().__init__(f"{self.path}: {problem}" if self.path else problem)
