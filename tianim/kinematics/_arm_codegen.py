"""Straight-line Python for one arm's substeps, traced from :func:`._arm_scalar.accelerations`.

Interpreting the generic loops of :func:`._arm_scalar.accelerations` costs ~6 us per
substep for two links (list indexing and loop overhead dominate). Here the same
function is run once on symbolic inputs; every arithmetic operation it performs
is recorded, in order, as one line of Python, and the lines are compiled into a
function of plain local floats. Because the recorded operations are the
reference function's own, in its own order (operations on two constants are
folded at trace time with the same IEEE arithmetic), the compiled function
returns bit-identical results: the tests check it. Two parts are written out as text
rather than traced, because they branch on the state: the integrator's update (clamps and
hard stops: :func:`._arm_scalar.step` / :func:`~._arm_scalar.step_rk4`; the RK4 combination in it
is :func:`._arm_scalar.rk4_average` run on source text, :class:`_Text`)
and the soft-limit branches of :func:`._arm_scalar._soft_limits` (their linear algebra, the
column of ``M^-1``, is traced).

Why ``exec``: this is the "generated from the one source" option for the single
environment's fast path, not a second copy of the dynamics. Measured on this
machine (loaded), two links, two semi-implicit Euler substeps: ~5.5 us per call
generated (the earlier fully inlined form: ~4.5 us); Reacher-v5's RK4 with its soft
elbow limit: the single ArmReach-v2 step ~90 us against ~300 us interpreted.
The generated source is kept on the function (``fn.source``) for inspection;
its only inputs are floats from a validated chain (``repr`` of finite floats).
"""

from __future__ import annotations

import math

from . import _arm_scalar as scalar


class _Sym:
    """A traced float64 value: the name of a local variable in the generated code."""

    __slots__ = ("name", "tape")

    def __init__(self, name: str, tape: "_Tape"):
        self.name = name
        self.tape = tape

    def _bin(self, op: str, a, b):
        return self.tape.emit(f"{_src(a)} {op} {_src(b)}")

    def __add__(self, o):
        return self._bin("+", self, o)

    def __radd__(self, o):
        return self._bin("+", o, self)

    def __sub__(self, o):
        return self._bin("-", self, o)

    def __rsub__(self, o):
        return self._bin("-", o, self)

    def __mul__(self, o):
        return self._bin("*", self, o)

    def __rmul__(self, o):
        return self._bin("*", o, self)

    def __truediv__(self, o):
        return self._bin("/", self, o)

    def __rtruediv__(self, o):
        return self._bin("/", o, self)


class _Text:
    """An expression as fully parenthesised Python source (each operation in the order it ran), for
    the parts of a step written out rather than traced: ``rk4_average`` run on ``_Text`` gives its text."""

    __slots__ = ("text",)

    def __init__(self, text: str):
        self.text = text

    def _bin(self, op: str, a, b):
        return _Text(f"({_text(a)} {op} {_text(b)})")

    def __add__(self, o):
        return self._bin("+", self, o)

    def __radd__(self, o):
        return self._bin("+", o, self)

    def __mul__(self, o):
        return self._bin("*", self, o)

    def __rmul__(self, o):
        return self._bin("*", o, self)

    def __truediv__(self, o):
        return self._bin("/", self, o)


def _text(v) -> str:
    return v.text if isinstance(v, _Text) else _src(v)


def _src(v) -> str:
    if isinstance(v, _Sym):
        return v.name
    v = float(v)
    if not math.isfinite(v):
        raise ValueError(f"cannot emit the non-finite constant {v!r}")
    return repr(v)


class _Tape:
    """Records operations as lines ``tK = ...``; also acts as the ``ops`` module."""

    def __init__(self):
        self.lines: list[str] = []

    def emit(self, expr: str) -> _Sym:
        name = f"t{len(self.lines)}"
        self.lines.append(f"{name} = {expr}")
        return _Sym(name, self)

    def _fn(self, fname: str, x):
        if not isinstance(x, _Sym):
            return getattr(math, fname)(x)
        return self.emit(f"{fname}({x.name})")

    def sin(self, x):
        return self._fn("sin", x)

    def cos(self, x):
        return self._fn("cos", x)

    def sqrt(self, x):
        return self._fn("sqrt", x)

    @staticmethod
    def let(x):
        """Every recorded operation is already a variable of its own (``tK``)."""
        return x


def _acc_source(params: tuple, dt: float) -> str:
    """Source of ``_acc(q0.., v0.., u0..) -> (a0, ..)``: :func:`._arm_scalar.accelerations` as
    straight-line code (the factor, the solve and, for soft limits, the column of ``M^-1`` of each
    limited joint traced; the limit branches written out as :func:`._arm_scalar._soft_limits` runs them)."""
    n, lower, upper, soft, invw = params[0], params[5], params[6], params[12], params[13]
    tape = _Tape()
    qs = [_Sym(f"q{i}", tape) for i in range(n)]
    vs = [_Sym(f"v{i}", tape) for i in range(n)]
    us = [_Sym(f"u{i}", tape) for i in range(n)]
    lo, r = scalar.factor(params, qs, vs, us, ops=tape)
    acc = scalar._relative(scalar._solve(lo, r, n, tape), n, tape)
    limited = [i for i in range(n) if soft is not None and (math.isfinite(lower[i]) or math.isfinite(upper[i]))]
    cols = {}
    for i in limited:
        cols[i] = scalar.inverse_column(lo, i, n, tape)
    lines = list(tape.lines)
    lines += [f"a{k} = {_src(acc[k])}" for k in range(n)]
    if limited:
        kk, bb = scalar.soft_gains(params, dt)
        for i in limited:
            lines += [
                f"f{i} = None",
                f"r = q{i} - {lower[i]!r}",
                "sign = 1.0",
                "if not r < 0.0:",
                f"    r = {upper[i]!r} - q{i}",
                "    sign = -1.0",
                "if r < 0.0:",
                "    imp = impedance(SOLIMP, r)",
                f"    aref = {-bb!r} * (sign * v{i}) - {kk!r} * imp * r",
                f"    jar = sign * a{i} - aref",
                "    if jar < 0.0:",
                f"        rr = (1.0 - imp) * {invw[i]!r} / imp",
                f"        if rr < {scalar.MINVAL!r}: rr = {scalar.MINVAL!r}",
                f"        f{i} = sign * (-jar / ({_src(cols[i][i])} + rr))",
            ]
        for i in limited:
            lines.append(f"if f{i} is not None:")
            lines += [f"    b{k} = a{k} + f{i} * {_src(cols[i][k])}" for k in range(n)]
            lines += [f"    a{k} = b{k}" for k in range(n)]
    args = ", ".join([f"q{i}" for i in range(n)] + [f"v{i}" for i in range(n)] + [f"u{i}" for i in range(n)])
    return (f"def _acc({args}):\n" + "".join(f"    {line}\n" for line in lines)
            + f"    return {', '.join(f'a{k}' for k in range(n))},\n")


def compile_stepper(params: tuple, dt: float, substeps: int, method: str = "semi_implicit_euler"):
    """A function ``f(q, qd, tau) -> (q, qd)`` (lists of n floats) equal bit for bit to
    ``_arm_scalar.step`` (``method="semi_implicit_euler"``) or ``_arm_scalar.step_rk4`` (``"rk4"``)
    with ``params, dt, substeps``, for every chain (gravity, armature, hard or soft limits): the
    accelerations are one generated function ``_acc`` called per stage; clamps at an infinite
    limit are left out (they never act). ~2-5x faster than the interpreted reference."""
    n, lower, upper, tmax, vmax, soft = params[0], params[5], params[6], params[8], params[9], params[12]
    qn = [f"q{i}" for i in range(n)]
    vn = [f"v{i}" for i in range(n)]
    un = [f"u{i}" for i in range(n)]

    def call(qq, vv):
        return f"_acc({', '.join(qq + vv + un)})"

    def finish(i, w_expr, p_expr):
        out = [f"w = {w_expr}", f"p = {p_expr}"]
        if math.isfinite(vmax):
            out += [f"if w > {vmax!r}: w = {vmax!r}", f"if w < {-vmax!r}: w = {-vmax!r}"]
        if soft is None and math.isfinite(lower[i]):
            out.append(f"if p < {lower[i]!r}:\n            p = {lower[i]!r}\n            if w < 0.0: w = 0.0")
        if soft is None and math.isfinite(upper[i]):
            out.append(f"elif p > {upper[i]!r}:\n            p = {upper[i]!r}\n            if w > 0.0: w = 0.0"
                       if math.isfinite(lower[i]) else
                       f"if p > {upper[i]!r}:\n            p = {upper[i]!r}\n            if w > 0.0: w = 0.0")
        return out + [f"n_q{i} = p; n_v{i} = w"]

    body = []
    if method == "rk4":
        half = 0.5 * dt
        body.append(f"{', '.join(f'k1_{i}' for i in range(n))}, = {call(qn, vn)}")
        body += [f"q2_{i} = q{i} + {half!r} * v{i}; v2_{i} = v{i} + {half!r} * k1_{i}" for i in range(n)]
        body.append(f"{', '.join(f'k2_{i}' for i in range(n))}, = "
                    f"{call([f'q2_{i}' for i in range(n)], [f'v2_{i}' for i in range(n)])}")
        body += [f"q3_{i} = q{i} + {half!r} * v2_{i}; v3_{i} = v{i} + {half!r} * k2_{i}" for i in range(n)]
        body.append(f"{', '.join(f'k3_{i}' for i in range(n))}, = "
                    f"{call([f'q3_{i}' for i in range(n)], [f'v3_{i}' for i in range(n)])}")
        body += [f"q4_{i} = q{i} + {dt!r} * v3_{i}; v4_{i} = v{i} + {dt!r} * k3_{i}" for i in range(n)]
        body.append(f"{', '.join(f'k4_{i}' for i in range(n))}, = "
                    f"{call([f'q4_{i}' for i in range(n)], [f'v4_{i}' for i in range(n)])}")
        for i in range(n):
            w = scalar.rk4_average(*map(_Text, (f"v{i}", f"k1_{i}", f"k2_{i}", f"k3_{i}", f"k4_{i}", repr(dt))))
            p = scalar.rk4_average(*map(_Text, (f"q{i}", f"v{i}", f"v2_{i}", f"v3_{i}", f"v4_{i}", repr(dt))))
            body += finish(i, w.text, p.text)
    else:
        body.append(f"{', '.join(f'k1_{i}' for i in range(n))}, = {call(qn, vn)}")
        for i in range(n):
            w = f"v{i} + {dt!r} * k1_{i}"
            lines = finish(i, w, "0.0")
            # semi-implicit Euler: the position uses the clamped new rate
            lines = [ln for ln in lines if not ln.startswith("p = ")]
            at = 1 + (2 if math.isfinite(vmax) else 0)
            lines.insert(at, f"p = q{i} + {dt!r} * w")
            body += lines
    body.append(", ".join(qn) + ", = " + ", ".join(f"n_q{i}" for i in range(n)) + ",")
    body.append(", ".join(vn) + ", = " + ", ".join(f"n_v{i}" for i in range(n)) + ",")
    clamps = "".join(f"    if u{i} > {tmax[i]!r}: u{i} = {tmax[i]!r}\n    if u{i} < {-tmax[i]!r}: u{i} = {-tmax[i]!r}\n"
                     for i in range(n) if math.isfinite(tmax[i]))
    src = (
        _acc_source(params, dt) + "\n\n"
        "def _stepper(q, qd, tau):\n"
        f"    {', '.join(qn)}, = q\n"
        f"    {', '.join(vn)}, = qd\n"
        f"    {', '.join(un)}, = tau\n"
        + clamps
        + f"    for _ in range({int(substeps)}):\n"
        + "".join(f"        {line}\n" for line in body)
        + f"    return [{', '.join(qn)}], [{', '.join(vn)}]\n"
    )
    namespace = {"sin": math.sin, "cos": math.cos, "sqrt": math.sqrt, "impedance": scalar.impedance,
                 "SOLIMP": None if soft is None else tuple(soft[2:])}
    exec(compile(src, f"<tianim.kinematics.arm {method} stepper n={n}>", "exec"), namespace)
    fn = namespace["_stepper"]
    fn.source = src
    return fn
