"""The merge tree of a binary hierarchy over consecutive frame ranges: the order in which
``assembly`` (thesis ch. 5) and ``surfels`` (Wand et al. 2007, sec. 3.2 "Iteration") join
adjacent ranges pairwise, level by level, until one spans them all."""

from __future__ import annotations


def merge_tree(count: int, *, onto: bool = False) -> list[tuple[int, int]]:
    """The merges of the hierarchy over ``count`` blocks, level by level: pairs of node ids,
    ``0 .. count - 1`` the blocks and ``count + k`` the result of the ``k``-th merge (an odd
    last node waits for the next level).

    With ``onto``, block 0 is a result made before (the frames so far of a run in windows,
    as :mod:`fourd.methods.assembly.stream` merges them): a hierarchy over the other blocks,
    merged onto it last.

    >>> merge_tree(5)
    [(0, 1), (2, 3), (5, 6), (7, 4)]
    >>> merge_tree(4, onto=True)
    [(1, 2), (4, 3), (0, 5)]
    """
    merges: list[tuple[int, int]] = []

    def hierarchy(level: list[int]) -> int:
        while len(level) > 1:
            following = []
            for i in range(0, len(level) - 1, 2):
                merges.append((level[i], level[i + 1]))
                following.append(count + len(merges) - 1)
            if len(level) % 2:
                following.append(level[-1])
            level = following
        return level[0]

    if onto and count > 1:
        merges.append((0, hierarchy(list(range(1, count)))))
    else:
        hierarchy(list(range(count)))
    return merges
