"""The ``"lanes"`` layout: symplectic Euler on a cloth grid, several particles per SIMD vector.

Why a layout of its own. Taichi's CPU backend compiles the body of a parallel loop into a
function that walks its chunk of indices one at a time, reloading every external array's pointer
and shape at each access (a store might alias them); LLVM vectorises neither that loop nor the
accesses. What does vectorise is the straight-line lanes of a ``ti.Vector``, and how well depends on
the code generation:

* scalarised (Taichi's default, ``real_matrix_scalarize``): a vector is split into scalars and LLVM's SLP
  vectoriser regroups them, to the width of taichi's optimiser target, which it builds from
  ``llvm::sys::getHostCPUName()`` with no feature string (``global_optimize_module_cpu``). On a CPU its
  LLVM 15 knows, that is the host (AVX2: ``<8 x float>``); on this project's AMD family 26 (Zen 5) host
  it is generic x86-64, 16 bytes whatever L; quadrants 1.3.3 regroups nothing (scalar code). Storage matters
  there too: ``ti.Vector.field`` loads regroup, the same body on ndarrays stays scalar;
* vector code generation (:mod:`tianim.kernels.simd`, what this layout's run kernels use): a vector of L
  lanes loaded from an ndarray of L-lane vectors stays one ``<L x float>`` LLVM value, and the JIT lowers it
  with the host's own CPU features (zmm registers with AVX-512), on taichi and quadrants alike. Same IEEE
  operations lane by lane: the same bits (tested).

The number of lanes ``L`` is an option (``lanes=``: :func:`lanes_for`; "auto" from the host's CPU flags,
:func:`host_lanes` up to :data:`LAYOUT_MAX_BYTES`: 16 float32 / 8 float64 with AVX-512, 8 / 4 with AVX2,
4 / 2 with SSE only). Measured at 128x128, float32, one thread, Zen 5: 4 / 8 / 16 lanes 3.9k / 7.2k / 10.8k
substeps/s; with the scalarised code generation this layout had before, 8 lanes ran 5.8k (two 4-wide chains).
The state of a call lives in a pool of ndarrays of L-lane vectors:

* the ``ny`` rows of each copy are cut into ``L`` bands of ``H = ceil(ny / L)`` rows (the last band
  padded); lane ``l`` of pack ``(r, c)`` holds particle ``(l H + r, c)``;
* the stencil neighbour ``(r + dr, c + dc)`` of every lane is lane for lane the pack
  ``(r + dr, c + dc)`` when ``0 <= r + dr < H``; across a band edge it is the pack
  ``(r + dr -/+ H, c + dc)`` with its lanes shifted by one (so ``H >= 2`` is needed for the
  2-row bend springs). Each copy stores ``H + 4`` rows of ``nx`` packs: 2 ghost rows below and above
  the band rows hold those lane-shifted copies, written by the pack they stand for when it stores its
  new state (so no extra loop or barrier). Every neighbour is then one vector load at the constant pack
  offset ``dr nx + dc``: no branch per neighbour row, no lanes reassembled from scalars (the branchy
  fetch it replaced made LLVM merge per-lane pointers and load each lane on its own: 1.4x slower).
  A lane whose neighbour row lies outside ``[0, ny)`` adds nothing (a select, no branch);
* the pool is pack-major: each pack's x and v of both ping-pong buffers, its mass, inverse mass and free
  flag are one block of :func:`block_width` vectors (pack kp's vector q at ``kp W + q``, W a compile-time
  constant), so a neighbour is a few consecutive vectors at a constant offset from the pack's own and a
  row's sweep reads one stream per stencil row. It replaced one ndarray row per component
  (``S[q, kp]``): 27 concurrent streams (39 with spring damping) and a runtime row stride; same-run A/B
  on a 2-vCPU AVX2 host, one thread, bit-identical: 1.31x faster at 128x128, 1.24x at 256x256;
* one parallel-loop index is a row of packs (``nx`` packs): one integer division per row, none per pack.
  The row is swept pack by pack, each pack's force in registers: it starts at ``m g`` (minus medium
  damping), then the 12 offsets of :data:`GRID_STENCIL`, in its order, unrolled at compile time (each
  offset's parameters, row mask and pack offset computed once per row; a neighbour column outside the
  grid skipped by a select, no branch), then the pack is updated and stored: no force buffer, so the only
  stores are the pack's new state. It replaced a sweep offset by offset over the row (as the vectorising
  numba kernel of the cloth bench sweeps its row views), which kept the force in a buffer: a load and a
  store per component and offset, and after each store LLVM reloads every ndarray's pointer and shape (they
  may alias). Same-run A/B on a 2-vCPU AVX2 host (8 lanes, medians, another process on the second core):
  1.35-1.41x faster on one thread at 128x128, 1.14-1.23x at 256x256, bit-identical. (Halving the square
  roots, each spring evaluated once and its force reused with the opposite sign, was not faster in a
  stripped-down copy: the kernel is bound by its loads, not its divisions.) The unrolled stencil makes the
  substep body large, so the parallel path runs :data:`SUBSTEPS_PER_LAUNCH` = 2 substeps per launch;
* every operation is that of :func:`tianim.physics.kernels.substep_funcs` in the same order (per pack the
  same terms summed in the same order), so the results are bit-identical to the other layouts (tested),
  for any thread count and batch.

Where the time goes. Per pack and offset the body is straight-line vector code: one vector load per
neighbour component, one square root and one division per L lanes, no branch and no division of integers.
Against the cloth bench's vectorising numba kernel (its row views, one division per spring, ``s / |d|``,
where tianim's arithmetic, ``1 / |d|`` then a product per component, is kept for bit-identity with the other
layouts), on the 2-vCPU AVX2 host, pack-major pool, 2 threads (interleaved rounds, medians, two quiet
runs): the ticket path 0.97-1.02x numba at 64x64, 0.99-1.00x at 128x128, 0.92-0.96x at 256x256 and
0.40-0.46x at 512x512 (numba's five row views stay in L1 there, each 512 particles of 12 bytes a
component; a pack row is 512 packs), the parallel path 0.54-0.56x at 128x128 (numba's OpenMP workers spin
between ``prange`` calls, 5 us a call, where a Taichi parallel loop costs about 30 us). One thread, before
the padding of :func:`block_width`: 21.1 against numba's 19.1 ns per particle-substep at 128x128 (0.9x;
0.6x before the per-pack body). Column strips of 16-128 packs (each substep swept strip by strip, to keep
the stencil's pack rows in L2) were measured and not kept: within 10 % of full rows, either way. An earlier
AVX-512 host (16 lanes, the offset-by-offset sweep) ran one thread at about numba's rate (128x128: 5.6 ns
per particle-substep).

A call packs the state (one parallel loop), runs its substeps ping-ponging between two buffers of
the pool, and unpacks. Up to :data:`SERIAL_MAX_PACKS` (batch x band rows x nx) one thread runs every
substep of the call in one launch (path ``"serial"``, a runtime loop over the substeps); above it every
thread runs every substep in one launch, taking rows from a counter (path ``"tickets"``); on a GPU,
:data:`SUBSTEPS_PER_LAUNCH` substeps per launch, one parallel loop each (path ``"parallel"``). The
solver layouts ``"lanes_serial"`` / ``"lanes_parallel"`` / ``"lanes_tickets"`` force a path
(``launch_lanes(path=)``).

Threads, measured. Taichi 1.7.4's CPU code generation gives every task of a parallel loop at least 512
indices (``cpu_block_dim_adaptive`` overrides ``ti.loop_config(block_dim=)``), so a loop over a cloth's 8 to
64 pack rows was one task on one thread (the parallel path ran 0.75-0.99x the serial path before this was
found). Both parallel paths therefore run T tasks, T = the threads (at most the rows), each one loop index
of :mod:`tianim.kernels.tasks`. The parallel path gives worker w the rows w,
w + T, ... and ends each substep in Taichi's barrier between loops (its workers sleep there, so it degrades
gently when other processes share the cores). The ticket path (``"tickets"``) puts every substep
of the call in one launch: a worker takes the next (substep, row) ticket from an atomic counter and starts
it once every row of the previous substep is done (a second counter on its own cache line,
:data:`TICKET_LINE`); no worker waits on a ticket not yet taken, so it cannot deadlock, and a worker that
finds no ticket ready for :data:`TICKET_PATIENCE` looks in a row leaves the launch holding none (the others
finish the call; at worst one worker runs the rest alone). Measured on an idle
2-vCPU AVX2 host against the serial path (interleaved rounds, medians), with the per-pack body: tickets
1.66x at 128x128, 1.71x at 256x256, 1.24x at 512x512; the parallel path 1.0x, 1.33x and 1.18x (its barrier
per substep: Taichi's workers sleep between loops, about 30 us a loop there). With busy processes beside it
(``while True: pass``), the patience keeps the ticket path near the serial path: two of them, 1.10x
(128x128) and 0.95x (256x256), the worst round 0.89x; one, 0.94x and 1.0x, the worst round 0.63x; the
parallel path 0.68-0.94x. (Before the patience, with two busy processes, one run fell to 0.15x and 0.47x.)
So ``"auto"`` takes the serial path up to :data:`SERIAL_MAX_PACKS` (tickets there: 0.91x at 32x32, 1.06-1.11x
at 48x48-64x64, 1.34x for 8 copies of 32x32: too close to pay for spinning threads) and the ticket path above
it; the parallel path stays for GPUs and as ``layout="lanes_parallel"``.
The serial and ticket paths' substep loops are runtime loops (the source buffer a runtime value: one
substep body to compile) and the parallel path unrolls 2 substeps, so that compiling stays short (128x128,
cold: serial 1.4 s, parallel 3.5 s, against 2.5 s and 5.4 s for the offset-by-offset sweep with 8 substeps
per launch). The pool grows by doubling (one compile
of the kernels per growth); the kernels take sizes as arguments, so a second scene or another batch
size compiles nothing new.
"""

import numpy as np

from tianim import _ti
from tianim.kernels.contact import lane_contact_response
from tianim.kernels import cached_variants, kernel_types
from tianim.kernels.simd import vector_codegen
from tianim.kernels.tasks import task_funcs
from tianim.physics.model import GRID_STENCIL
from tianim.runtime import current_arch, num_threads
from tianim.physics.packed import I_BAND, I_NX, I_NY, I_PATIENCE, I_ROWS, I_SRC, pack_params

#: Vector register width [bytes] of the host's widest float SIMD, by CPU flag (``/proc/cpuinfo``); SSE2 (16)
#: is the x86-64 baseline. Taichi compiles kernel bodies for the host CPU, so a vector of that many bytes
#: fills one register.
SIMD_BYTES = (("avx512f", 64), ("avx2", 32), ("avx", 32))
#: Lane counts a caller may ask for (``lanes=``), by float type; the smallest is one SSE register.
LANE_CHOICES = {"float32": (4, 8, 16), "float64": (2, 4, 8)}
#: Widest vector "auto" uses [bytes] for kernels left to Taichi's scalarising code generation (the particle
#: lanes, XPBD's lanes): on this project's AVX-512 host 16 float32 lanes ran slower than 8 there (LLVM regroups
#: the scalars to its target's width, see the note above), so they stop at one ymm register.
AUTO_MAX_BYTES = 32
#: Widest vector "auto" uses [bytes] in this layout, whose run kernels keep their vectors whole
#: (:mod:`tianim.kernels.simd`): one register of the host, zmm included. Measured at 128x128, float32, one
#: thread, Zen 5 (AVX-512): 16 lanes 10.8k substeps/s against 7.2k for 8 (64x64: 36k / 26k; 256x256: 2.9k /
#: 1.9k); their cold compile 2.1 s against 1.1 s (64x64, damping and a ground).
LAYOUT_MAX_BYTES = 64
#: Substeps per launch of the main kernel (even: the ping-pong ends in the first buffer).
#: (The per-pack body unrolls the stencil: 8 per launch compiled in 29 s cold at 128x128, 2 in 3.5 s, and ran
#: as fast.)
SUBSTEPS_PER_LAUNCH = 2
#: Most packs (batch x band rows x nx: L particles each) that "auto" runs on one thread, every substep in
#: one launch: up to it a barrier per substep (about 0.14 ms on 2 vCPUs) costs more than the second thread
#: gives. In packs, not particles, since a substep's time follows the packs (one vector op per pack): on a
#: 2-vCPU AVX2 host (8 lanes) one thread ran 1.8x the parallel path at 64x64 (512 packs) and the parallel
#: path 1.36x one thread at 128x128 (2,048 packs), 1.4x for 4 copies of 128x128, 1.5x for 16 of 64x64; on
#: an AVX-512 host (16 lanes) 128x128 (1,024 packs, 0.1 ms a substep) was too short for two threads.
SERIAL_MAX_PACKS = 1 << 10
#: Offset [int32] of the ticket path's finished-rows counter from its tickets-taken counter: 64 bytes, one
#: cache line each, so the workers polling one do not slow the one taking a ticket.
TICKET_LINE = 16
#: Looks at the next ticket without finding it ready after which a worker of the ticket path leaves its launch
#: (holding no ticket: the others finish the call). About 0.1 ms of spinning at 50 ns a look (a locked add on a
#: cache line the other workers write): longer than a row takes, shorter than a time slice.
TICKET_PATIENCE = 2000
#: CPU archs: where the ticket path can run (threads that each take one task and spin on shared counters),
#: where "auto" may take the serial path and the parallel path has one worker per thread.
CPU_ARCHES = ("x64", "arm64")
#: Smallest pool, in packs (grown by doubling).
MIN_CAPACITY = 1 << 12

_N_OFF = len(GRID_STENCIL)


def cpu_simd_bytes(flags=None) -> int:
    """Width [bytes] of the widest float vector register of the host (16, 32 or 64), from the CPU flags
    (``flags``: a set of ``/proc/cpuinfo`` flag names; None: read this host's, SSE2 where unreadable)."""
    if flags is None:
        flags = _host_flags()
    return next((b for flag, b in SIMD_BYTES if flag in flags), 16)


def _host_flags() -> frozenset:
    global _FLAGS
    if _FLAGS is None:
        try:
            with open("/proc/cpuinfo") as fh:
                line = next((ln for ln in fh if ln.startswith("flags")), "")
            _FLAGS = frozenset(line.partition(":")[2].split())
        except OSError:
            _FLAGS = frozenset()
    return _FLAGS


_FLAGS = None


def host_lanes(dtype, flags=None, max_bytes=AUTO_MAX_BYTES) -> int:
    """The ``lanes="auto"`` count for ``dtype``: one vector register of the host, at most ``max_bytes``
    (:data:`AUTO_MAX_BYTES`: 8 float32 / 4 float64 lanes with AVX2 or AVX-512, 4 / 2 with SSE only;
    :data:`LAYOUT_MAX_BYTES`, this layout's: 16 / 8 with AVX-512)."""
    itemsize = np.dtype(dtype).itemsize
    return min(cpu_simd_bytes(flags), max_bytes) // itemsize


def check_lanes(lanes, dtype=None):
    """``lanes`` ("auto" or a count of :data:`LANE_CHOICES` for ``dtype``; None: for any float type), or a
    ValueError naming it."""
    name = "float32 or float64" if dtype is None else np.dtype(dtype).name
    choices = sorted({c for v in LANE_CHOICES.values() for c in v}) if dtype is None else LANE_CHOICES.get(name, ())
    if isinstance(lanes, str) and lanes == "auto":
        return lanes
    if isinstance(lanes, (int, np.integer)) and not isinstance(lanes, bool) and int(lanes) in choices:
        return int(lanes)
    raise ValueError(f"lanes={lanes!r} is not a lane count for {name}; use 'auto' or one of {list(choices)}")


def lanes_for(dtype, ny=None, lanes="auto") -> int:
    """Particles per vector for the state's float type: ``lanes`` when a count, else :func:`host_lanes`
    (up to :data:`LAYOUT_MAX_BYTES`) halved while a grid of ``ny`` rows would get fewer than 2 rows per band
    (down to one SSE register)."""
    if lanes != "auto":
        return int(lanes)
    L = host_lanes(dtype, max_bytes=LAYOUT_MAX_BYTES)
    smallest = LANE_CHOICES[np.dtype(dtype).name][0]
    while ny is not None and L > smallest and -(-ny // L) < 2:
        L //= 2
    return L


def supports(model, dtype, lanes="auto") -> bool:
    """Whether ``model`` can run in this layout: a cloth grid with at least 2 rows per band."""
    g = model.grid
    return g is not None and -(-g.ny // lanes_for(dtype, g.ny, lanes)) >= 2


def block_width(dim: int) -> int:
    """L-lane vectors per pack in the pool (:class:`_Pool`): x and v of the two ping-pong buffers, then
    mass, inverse mass and free, padded to a multiple of 4 (16 in 3-D, 12 in 2-D): with 32-byte vectors
    every block then starts on a cache line and a pack's x and v of one buffer fill 3 lines (3-D) instead of
    3 or 4 (same-run A/B, 2-vCPU AVX2 host, one thread: 1.07-1.08x at 128x128, 1.09-1.13x at 512x512)."""
    return -(-(4 * dim + 3) // 4) * 4


class _Pool:
    """The ndarrays of one (float type, dimension): state, one block of :func:`block_width` L-lane vectors
    per pack, pack after pack ([x, v, xs, vs components, mass, inverse mass, 1 free / 0 pinned]: pack kp's
    vector q at ``kp W + q``), prm [gravity, rho, k, rest, damp] (a pack's force sum stays in registers).
    Ndarrays, not fields: the run kernels compile with vector code generation (:mod:`tianim.kernels.simd`)."""

    def __init__(self, ti, real, dim, lanes, capacity):
        lane_vec = ti.types.vector(lanes, real)
        self.state = ti.ndarray(lane_vec, (block_width(dim) * capacity,))
        self.prm = ti.ndarray(real, dim + 1 + 3 * _N_OFF)
        self.tickets = ti.ndarray(ti.i32, 2 * TICKET_LINE)  # the ticket path's counters: taken, rows finished
        self.capacity = capacity


_POOLS: dict = _ti.per_program({})  # fields of the live program: emptied when it is replaced


def _pool(real_name, dim, L, packs):
    """The pool for (real_name, dim, L lanes) with room for ``packs`` packs (grown by doubling)."""
    key = (real_name, dim, L)
    pool = _POOLS.get(key)
    if pool is None or pool.capacity < packs:
        cap = max(MIN_CAPACITY, pool.capacity if pool is not None else 0)
        while cap < packs:
            cap *= 2
        t = kernel_types(real_name, dim)
        pool = _POOLS[key] = _Pool(t.ti, t.real, dim, L, cap)
    return pool


@cached_variants
def lane_kernels(real_name, dim, L, colliders, spring_damping, medium_damping):
    """``(pack, run, unpack)`` for vectors of L lanes: ``run[nsub]`` advances nsub in {1, 2,
    SUBSTEPS_PER_LAUNCH} substeps, ``run["serial"]`` any number on one thread."""
    t = kernel_types(real_name, dim)
    ti, real = t.ti, t.real
    lane_vec = ti.types.vector(L, real)
    task_stride, item_of = task_funcs()
    lanes_arr = ti.types.ndarray(dtype=lane_vec, ndim=1)  # packs x W L-lane vectors, pack-major
    W = block_width(dim)
    RM = 4 * dim  # mass, inverse mass, free: vectors RM .. RM + 2 of a pack's block
    lane_respond = lane_contact_response(real_name, dim, L)
    h = dim + 1  # prm: gravity[dim], rho, k[12], rest[12], damp[12] (the P layout of kernels.py)

    @ti.kernel
    def pack(S: lanes_arr, prm: t.real_arr, x: t.vec_arr, v: t.vec_arr,
             pinned: t.mask_arr, P: t.real_arr, I: t.int_arr):
        nx, H = I[I_NX], I[I_BAND]
        n = x.shape[1]
        ny = n // nx
        npk = H * nx
        for k in range(x.shape[0] * npk):
            if k == 0:
                for q in range(h):
                    prm[q] = P[q]
                for q in range(3 * _N_OFF):
                    prm[h + q] = P[h + 2 * n + q]
            b = k // npk
            kp, r, c = pack_index(k, nx, H)
            X = ti.Matrix.zero(real, 2 * dim + 3, L)  # x, v components, mass, inverse mass, free; one column per lane
            for lane in ti.static(range(L)):
                row = lane * H + r
                if row < ny:  # padding lanes stay zero: no mass, pinned, at rest at the origin
                    i = row * nx + c
                    xi = x[b, i]
                    vi = v[b, i]
                    for a in ti.static(range(dim)):
                        X[a, lane] = xi[a]
                        X[dim + a, lane] = vi[a]
                    X[2 * dim, lane] = P[h + i]
                    X[2 * dim + 1, lane] = P[h + n + i]
                    if pinned[b, i] == 0:
                        X[2 * dim + 2, lane] = 1
            for a in ti.static(range(2 * dim)):
                S[kp * W + a] = ti.Vector([X[a, lane] for lane in range(L)])
            for a in ti.static(range(3)):
                S[kp * W + RM + a] = ti.Vector([X[2 * dim + a, lane] for lane in range(L)])
            write_ghosts(S, 0, kp, r, nx, H)

    @ti.kernel
    def unpack(S: lanes_arr, x: t.vec_arr, v: t.vec_arr, I: t.int_arr):
        nx, H, src = I[I_NX], I[I_BAND], I[I_SRC]
        n = x.shape[1]
        ny = n // nx
        npk = H * nx
        for k in range(x.shape[0] * npk):
            b = k // npk
            kp, r, c = pack_index(k, nx, H)
            u = [S[kp * W + src * 2 * dim + a] for a in ti.static(range(2 * dim))]
            for lane in ti.static(range(L)):
                row = lane * H + r
                if row < ny:
                    i = row * nx + c
                    x[b, i] = ti.Vector([u[a][lane] for a in range(dim)])
                    v[b, i] = ti.Vector([u[dim + a][lane] for a in range(dim)])

    @ti.func
    def pack_index(k, nx, H):
        """(index in the pool, band row r, column c) of pack k of the call (copy by copy, row-major): each
        copy holds H + 4 rows of nx packs, 2 ghost rows below and above its H band rows."""
        npk = H * nx
        b = k // npk
        p = k - b * npk
        r = p // nx
        c = p - r * nx
        return b * (npk + 4 * nx) + (r + 2) * nx + c, r, c

    @ti.func
    def write_ghosts(S: ti.template(), q0, kp, r, nx, H):
        """Copy the x, v components (vectors q0 .. q0 + 2 dim of the block) of pack kp at band row r into the
        ghost packs that stand for it: band row rr = r - H (r >= H - 2; lane l holds lane l - 1 of pack r, the
        particle H rows further down) and rr = r + H (r < 2; lane l holds lane l + 1). A neighbour at any band row
        rr in [-2, H + 2) is then the pack kp + (rr - r) nx, lane for lane: one vector load, no branch.
        The lanes shifted in from beyond the band (lane 0 below, lane L - 1 above) repeat their neighbour and
        are never used (their global row lies outside [0, ny): masked by substep_row)."""
        if r >= H - 2:
            g = kp - H * nx
            for a in ti.static(range(2 * dim)):
                u = S[kp * W + q0 + a]
                S[g * W + q0 + a] = ti.Vector([u[max(lane - 1, 0)] for lane in range(L)])
        if r < 2:
            g = kp + H * nx
            for a in ti.static(range(2 * dim)):
                u = S[kp * W + q0 + a]
                S[g * W + q0 + a] = ti.Vector([u[min(lane + 1, L - 1)] for lane in range(L)])

    @ti.func
    def spring_force(s, n, damp, dot):
        """One component of kernels.pair_force: s n, minus the damping (damp dot) n."""
        f = s * n
        if ti.static(spring_damping):
            f = f - damp * dot * n  # not `-=`: vector code generation (kernels.simd) has no augmented minus
        return f

    @ti.func
    def substep_row(S: ti.template(), prm: ti.template(), coll: ti.template(), src, q, nx, ny, H,
                    dt):
        """One substep of pack row q, pack by pack: each pack's force starts at m g (minus medium damping) and
        adds the 12 terms of GRID_STENCIL in its order, in registers (the stencil unrolled at compile time; each
        offset's parameters, row mask and pack offset computed once per row), then the pack is updated and
        stored. The same operations in the same order as :func:`substep` (same bits): a term whose neighbour
        column lies outside the grid is skipped (``select(ok, f + t, f)``), one whose neighbour row does adds
        zero, as there."""
        b = q // H
        r = q - b * H
        k0 = b * (H + 4) * nx + (r + 2) * nx  # pack_index of column 0
        xs = src * 2 * dim
        zero = lane_vec(0)
        lane_row = ti.Vector([lane * H for lane in range(L)])
        ko = [prm[h + o] for o in ti.static(range(_N_OFF))]
        lo = [prm[h + _N_OFF + o] for o in ti.static(range(_N_OFF))]
        do = [prm[h + 2 * _N_OFF + o] for o in ti.static(range(_N_OFF))]
        dj = [(GRID_STENCIL[o][1] * nx + GRID_STENCIL[o][0]) * W for o in ti.static(range(_N_OFF))]
        valid = [(lane_row + r + GRID_STENCIL[o][1] >= 0) & (lane_row + r + GRID_STENCIL[o][1] < ny)
                 for o in ti.static(range(_N_OFF))]
        g = [prm[a] for a in ti.static(range(dim))]
        rho = prm[dim]
        for c in range(nx):
            kp = k0 + c
            e = kp * W + xs  # the pack's source x and v
            m = S[kp * W + RM]
            xi = [S[e + a] for a in ti.static(range(dim))]
            vi = [S[e + dim + a] for a in ti.static(range(dim))]
            f = [m * g[a] for a in ti.static(range(dim))]  # m g
            if ti.static(medium_damping):
                for a in ti.static(range(dim)):
                    f[a] = f[a] - rho * vi[a]
            for o in ti.static(range(_N_OFF)):
                dc = ti.static(GRID_STENCIL[o][0])
                j = e + dj[o]  # the neighbour pack's source x (a ghost pack across a band edge)
                d = [xi[a] - S[j + a] for a in ti.static(range(dim))]
                len2 = d[0] * d[0]
                for a in ti.static(range(1, dim)):
                    len2 += d[a] * d[a]
                length = ti.sqrt(len2)
                inv_len = ti.select(length > 0, 1 / length, zero)
                sv = -ko[o] * (length - lo[o])
                nrm = [d[a] * inv_len for a in ti.static(range(dim))]
                dot = zero
                if ti.static(spring_damping):
                    dv = [vi[a] - S[j + dim + a] for a in ti.static(range(dim))]
                    dot = dv[0] * nrm[0]
                    for a in ti.static(range(1, dim)):
                        dot += dv[a] * nrm[a]
                for a in ti.static(range(dim)):
                    t = ti.select(valid[o], spring_force(sv, nrm[a], do[o], dot), zero)
                    if ti.static(dc == 0):
                        f[a] = f[a] + t
                    else:
                        f[a] = ti.select((c + dc >= 0) & (c + dc < nx), f[a] + t, f[a])
            update(S, prm, coll, f, src, kp, r, nx, H, dt)

    @ti.func
    def update(S: ti.template(), prm: ti.template(), coll: ti.template(), f: ti.template(),
               src, kp, r, nx, H, dt):
        """The velocity and position update of pack kp from its summed force f (dim lane vectors), contacts,
        ghosts."""
        e = kp * W + src * 2 * dim
        d = kp * W + (1 - src) * 2 * dim
        zero = lane_vec(0)
        free = S[kp * W + RM + 2] > 0
        im = S[kp * W + RM + 1]
        xn = [zero for _ in ti.static(range(dim))]
        vn = [zero for _ in ti.static(range(dim))]
        for a in ti.static(range(dim)):
            vn[a] = S[e + dim + a] + dt * ti.select(free, f[a] * im, zero)
            xn[a] = S[e + a] + dt * vn[a]
        if ti.static(colliders):  # the L lanes at once
            g2 = prm[0] * prm[0]
            for a in ti.static(range(1, dim)):
                g2 += prm[a] * prm[a]
            g_norm = ti.sqrt(g2)
            lane_respond(xn, vn, free, coll, g_norm, dt)
        for a in ti.static(range(dim)):
            S[d + dim + a] = vn[a]
            S[d + a] = xn[a]
        xd = (1 - src) * 2 * dim
        write_ghosts(S, xd, kp, r, nx, H)  # after the contacts: the ghosts copy the stored values

    def make_run(nsub):
        @ti.kernel
        def run(S: lanes_arr, prm: t.real_arr, coll: t.real2_arr, I: t.int_arr, dt: real,
                workers: ti.i32):
            rows, nx, ny, H = I[I_ROWS], I[I_NX], I[I_NY], I[I_BAND]
            stride = task_stride(workers)
            for s in ti.static(range(nsub)):  # each top-level loop ends in a barrier
                for w in range(workers * stride):  # one task per worker (tianim.kernels.tasks)
                    q = item_of(w, stride)
                    if q >= 0:
                        while q < rows:  # rows w, w + workers, ...
                            substep_row(S, prm, coll, s % 2, q, nx, ny, H, dt)
                            q += workers

        return vector_codegen(run)

    runs = {n: make_run(n) for n in (1, 2, SUBSTEPS_PER_LAUNCH)}

    @ti.kernel
    def run_serial(S: lanes_arr, prm: t.real_arr, coll: t.real2_arr, I: t.int_arr, dt: real,
                   nsub: ti.i32):
        # One thread, every substep of the call in one launch: no barriers, no worker wake-ups; the substep
        # loop is a runtime loop and the source buffer a runtime value (one substep body to compile).
        rows, nx, ny, H = I[I_ROWS], I[I_NX], I[I_NY], I[I_BAND]
        ti.loop_config(serialize=True)
        for s in range(nsub):
            for q in range(rows):
                substep_row(S, prm, coll, s % 2, q, nx, ny, H, dt)

    runs["serial"] = vector_codegen(run_serial)

    @ti.kernel
    def run_tickets(S: lanes_arr, prm: t.real_arr, coll: t.real2_arr, I: t.int_arr, dt: real,
                    nsub: ti.i32, workers: ti.i32, C: t.int_arr):
        # Every substep of the call in one launch on `workers` tasks. Ticket g is pack row g % rows of substep
        # g // rows; C[0] counts the tickets taken, C[TICKET_LINE] the rows finished. A worker looks at the next
        # ticket and takes it (an atomic add: it may get a later one) once every row of its previous substep is
        # done; then it waits, if it must, for the previous substep of the ticket it got, runs the row and
        # counts it. Deadlock-free however the tasks are scheduled: no worker waits on a ticket not yet taken,
        # and a worker alone takes every ticket in order. A worker that looks ``I[I_PATIENCE]`` times in a row without
        # finding a ticket ready (another worker holds the rows it needs, or the tickets are all taken) leaves the
        # launch holding no ticket: the rest finish without it, so a worker descheduled by another process
        # stalls the others for at most that long instead of a time slice of spinning.
        rows, nx, ny, H, patience = I[I_ROWS], I[I_NX], I[I_NY], I[I_BAND], I[I_PATIENCE]
        C[0] = 0
        C[TICKET_LINE] = 0
        total = nsub * rows
        stride = task_stride(workers)
        for w in range(workers * stride):  # one task per worker (tianim.kernels.tasks)
            if item_of(w, stride) >= 0:
                idle = 0
                while idle <= patience:
                    g = ti.atomic_add(C[0], 0)
                    if g >= total:
                        idle = patience + 1  # every ticket taken: leave
                    elif ti.atomic_add(C[TICKET_LINE], 0) >= (g // rows) * rows:
                        g = ti.atomic_add(C[0], 1)
                        if g < total:
                            s = g // rows
                            while ti.atomic_add(C[TICKET_LINE], 0) < s * rows:  # the previous substep's rows
                                pass
                            substep_row(S, prm, coll, s % 2, g - s * rows, nx, ny, H, dt)
                            ti.atomic_add(C[TICKET_LINE], 1)
                        idle = 0
                    else:
                        idle += 1

    runs["tickets"] = vector_codegen(run_tickets)
    return pack, runs, unpack


#: Thread paths of the layout (``launch_lanes(path=)``): "auto" chooses from the scene size.
PATHS = ("auto", "serial", "parallel", "tickets")


def launch_lanes(model, state, dt: float, substeps: int, data, path: str = "auto", lanes="auto") -> None:
    """Advance ``state`` by ``substeps`` symplectic Euler steps of ``dt`` in the lanes layout
    (no validation: :func:`tianim.physics.explicit.launch` is the caller). ``data`` is
    ``model.kernel_data(state.dtype)``. ``path``: ``"serial"`` (one thread, the whole call in one
    launch), ``"parallel"`` (parallel loops, :data:`SUBSTEPS_PER_LAUNCH` substeps per launch),
    ``"tickets"`` (every substep in one launch on all threads, rows taken from a counter; CPU only) or
    ``"auto"`` (on a CPU serial up to :data:`SERIAL_MAX_PACKS` packs or with one thread, else tickets; on a
    GPU parallel). ``lanes``:
    particles per vector (:func:`lanes_for`; "auto": from the host CPU). Every path and lane count is
    bit-identical."""
    g = model.grid
    real_name = state.dtype.name
    L = lanes_for(state.dtype, g.ny, lanes)
    H = -(-g.ny // L)
    pool = _pool(real_name, model.dim, L, state.batch * (H + 4) * g.nx)  # with the ghost rows
    pack, runs, unpack = lane_kernels(real_name, model.dim, L, len(model.colliders) > 0,
                                      model.has_spring_damping, model.medium_damping > 0)
    cpu = current_arch() in CPU_ARCHES  # (after the kernels: Taichi is initialised)
    if path == "tickets" and not cpu:
        raise ValueError(f"layout='lanes_tickets' spins on counters shared by CPU threads; got arch "
                         f"{current_arch()!r}; use layout='lanes' or 'lanes_parallel' there")
    S, prm = pool.state, pool.prm
    _, I = pack_params(state.dtype, model.dim, nx=g.nx, ny=g.ny, band=H, rows=state.batch * H,
                       src=substeps % 2, patience=TICKET_PATIENCE)  # src: the buffer the last substep writes
    pack(S, prm, state.x, state.v, state.pinned.view(np.uint8), data["params"], I)
    dt = float(state.dtype.type(dt))  # a Python float of the state dtype's value (quadrants caches on primitives)
    args = (S, prm, data["coll"], I, dt)
    if path == "auto":  # CPU: one thread up to SERIAL_MAX_PACKS, every thread on tickets above; GPU: parallel
        if not cpu:
            path = "parallel"  # one GPU thread would crawl
        elif state.batch * H * g.nx <= SERIAL_MAX_PACKS or (num_threads() or 1) < 2:
            path = "serial"
        else:
            path = "tickets"
    if path == "serial":
        runs["serial"](*args, substeps)
        unpack(S, state.x, state.v, I)
        return
    workers = max(1, min(num_threads() or 1, state.batch * H)) if cpu else state.batch * H  # GPU: a row each
    if path == "tickets":
        runs["tickets"](*args, substeps, workers, pool.tickets)
        unpack(S, state.x, state.v, I)
        return
    for _ in range(substeps // SUBSTEPS_PER_LAUNCH):
        runs[SUBSTEPS_PER_LAUNCH](*args, workers)
    rest = substeps % SUBSTEPS_PER_LAUNCH
    for _ in range(rest // 2):
        runs[2](*args, workers)
    if rest % 2:
        runs[1](*args, workers)
    unpack(S, state.x, state.v, I)  # rest % 2 == substeps % 2: the parity of the substeps run
