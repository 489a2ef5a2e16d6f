"""One CPU task per item of a short parallel loop over heavy items (copies of a batch, rows of packs).

Taichi 1.7.4's CPU code generation gives every task of a parallel loop at least 512 indices (its adaptive
block size, ``cpu_block_dim_adaptive``, which overrides ``ti.loop_config(block_dim=)``), so a parallel loop
of fewer than about 1,024 indices runs as one task on one thread, however heavy each index is: a batch of
4 XPBD cloths, one loop index per copy, ran on one of the two threads. Measured on 2 vCPUs (a kernel of 4
items of 10^7 sines each): 0.92 s on one thread, 0.88 s on two; spread as below, 0.62 s on two.

The remedy, used by every such loop: run the loop over ``n * stride`` indices, ``stride = task_stride(n)``
(:data:`TASK_ITEMS` below :data:`SPREAD_MAX_ITEMS` items, else 1: enough indices for the adaptive tasks
already), and let only index ``w`` with ``w % stride == 0`` work, on item ``w // stride``; each task then
holds one working index::

    stride = task_stride(n)
    for w in range(n * stride):
        b = item_of(w, stride)
        if b >= 0:
            ...  # the body of item b

Each item runs the same operations as before (the same bits for any thread count). The idle indices cost
a test each (under 1 us per item). On a GPU the working indices are one per block of idle ones: the same
parallelism over items as the plain loop.
"""

from tianim import _ti
from tianim.kernels import cached_variants

#: Loop indices per item of a spread loop: Taichi 1.7.4's smallest CPU task (see the module note).
TASK_ITEMS = 512
#: Items from which a loop is left plain: its adaptive tasks (512 to 1,024 indices) already number two or
#: more, and spreading would add n x 511 idle indices.
SPREAD_MAX_ITEMS = 1024


@cached_variants
def task_funcs():
    """``(task_stride, item_of)`` as ``ti.func``s: ``task_stride(n)`` the loop indices per item for a loop
    over n items, ``item_of(w, stride)`` the item index ``w`` works on, or -1 for an idle index."""
    ti = _ti.get()

    @ti.func
    def task_stride(n):
        stride = 1
        if n < SPREAD_MAX_ITEMS:
            stride = TASK_ITEMS
        return stride

    @ti.func
    def item_of(w, stride):
        item = -1
        if w % stride == 0:
            item = w // stride
        return item

    return task_stride, item_of
