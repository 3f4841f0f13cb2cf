"""A binary min-heap of node ids keyed by an array, with each node's heap position tracked so
a key can be lowered in place (the heap of Prim's and Dijkstra's algorithms), for numba code.

``keys [N]`` holds every node's key, ``heap [N]`` the nodes in heap order (the first ``size``
entries), ``where [N]`` each node's position in ``heap`` (-1 when not in it).
"""

from __future__ import annotations

import numba


@numba.njit(cache=True)
def sift_up(keys, heap, where, i):
    """Move ``heap[i]`` up the binary heap of node ids ordered by ``keys`` (``where``: each
    node's heap position)."""
    node = heap[i]
    key = keys[node]
    while i > 0:
        up = (i - 1) >> 1
        if keys[heap[up]] <= key:
            break
        heap[i] = heap[up]
        where[heap[i]] = i
        i = up
    heap[i] = node
    where[node] = i


@numba.njit(cache=True)
def heap_pop(keys, heap, where, size):
    """Remove the node of smallest key; returns it and the new size."""
    top = heap[0]
    where[top] = -1
    size -= 1
    if size == 0:
        return top, size
    node = heap[size]
    key = keys[node]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and keys[heap[child + 1]] < keys[heap[child]]:
            child += 1
        if key <= keys[heap[child]]:
            break
        heap[i] = heap[child]
        where[heap[i]] = i
        i = child
    heap[i] = node
    where[node] = i
    return top, size
