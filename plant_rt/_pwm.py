"""Centre-aligned PWM with dead time: the switching timeline of one period.

Carrier. A symmetric triangle at ``f_sw = 1 / T_s`` whose extremum chosen by
``sample_at`` falls on every period boundary ``t = k T_s``, where the ADC
samples (DESIGN.md, "Timing model"). Leg ``x`` is commanded high (upper
switch) while the carrier lies below its duty ``d_x`` (period start at 0)::

    "peak":   low, high on [(1 - d) T/2, (1 + d) T/2), low
    "valley": high on [0, d T/2), low, high on [T - d T/2, T)

so each leg's high time is ``d_x T`` and the pulses of the three legs are
centred on the same instant (the zero vectors 000 and 111 split evenly
around the period boundary and mid-period). Duty 0 or 1 holds the leg at a
rail for the whole period (no edge unless the previous period ended at the
other rail).

Dead time. A gate driver turns a switch on ``t_dead`` after its command
rises and off at once when it falls. After every command edge at ``e`` both
switches of the leg are off (``DEAD``) on ``[e, e + t_dead)``; then the
commanded switch conducts. A command pulse shorter than ``t_dead`` never
turns its switch on (the dead interval restarts at the second edge), and a
dead interval that runs past the period boundary carries into the next
period. What a ``DEAD`` leg's pole voltage is depends on the phase current
(diode conduction, or a floating phase when the current is zero): the
plant decides that (:class:`plant_rt.Plant`).

This module is timing only: duties in, sub-intervals with constant leg
states out.
"""

from __future__ import annotations

LOW = 0
"""Lower switch gated on: the pole sits on the negative rail (less a device drop)."""
HIGH = 1
"""Upper switch gated on: the pole sits on the positive rail (less a device drop)."""
DEAD = 2
"""Both switches off: a diode or the floating phase sets the pole voltage."""
_OFF = -1  # command after a disabled period: neither switch


class PwmTimeline:
    """Gate states of the three legs over each PWM period.

    Parameters
    ----------
    T_s : float
        PWM period (s).
    t_dead : float
        Dead time (s), >= 0 and below ``T_s / 2``.
    sample_at : {"peak", "valley"}
        Carrier extremum on the period boundary.
    """

    __slots__ = ("T_s", "_cmd", "_dead_end", "_peak", "t_dead")

    def __init__(self, T_s: float, t_dead: float, sample_at: str) -> None:
        if not 0.0 <= t_dead < 0.5 * T_s:
            raise ValueError(f"dead time must be in [0, T_s / 2), got {t_dead} s at T_s = {T_s} s")
        self.T_s = float(T_s)
        self.t_dead = float(t_dead)
        self._peak = sample_at == "peak"
        level = LOW if self._peak else HIGH
        # Commanded level at the end of the last period, and the end of a dead
        # interval that runs into the next period (s, from its start; <= 0: none).
        self._cmd = [level, level, level]
        self._dead_end = [0.0, 0.0, 0.0]

    def disable(self) -> None:
        """All switches opened for a period: each leg's next command is a turn-on edge."""
        self._cmd = [_OFF, _OFF, _OFF]
        self._dead_end = [0.0, 0.0, 0.0]

    def period(
        self, d_a: float, d_b: float, d_c: float, cuts: tuple[float, ...]
    ) -> list[tuple[float, float, int, int, int]]:
        """Sub-intervals of the next period with constant gate states.

        Parameters
        ----------
        d_a, d_b, d_c : float
            Duties, already clamped to [0, 1].
        cuts : tuple of float
            Extra instants in (0, T_s) where a sub-interval must end (the
            integration grid, the sensor instant), ascending.

        Returns
        -------
        list of (t_start, t_end, s_a, s_b, s_c)
            Times from the period start (s), covering [0, T_s) without gaps;
            states :data:`LOW`, :data:`HIGH` or :data:`DEAD`.
        """
        T = self.T_s
        la = self._leg(0, d_a)
        lb = self._leg(1, d_b)
        lc = self._leg(2, d_c)
        times = {T}
        for pts in (la, lb, lc):
            for t, _ in pts:
                if t > 0.0:
                    times.add(t)
        for t in cuts:
            times.add(t)
        ja = jb = jc = 0
        na, nb, nc = len(la), len(lb), len(lc)
        sa, sb, sc = la[0][1], lb[0][1], lc[0][1]
        out: list[tuple[float, float, int, int, int]] = []
        t0 = 0.0
        for t1 in sorted(times):
            while ja + 1 < na and la[ja + 1][0] <= t0:
                ja += 1
                sa = la[ja][1]
            while jb + 1 < nb and lb[jb + 1][0] <= t0:
                jb += 1
                sb = lb[jb][1]
            while jc + 1 < nc and lc[jc + 1][0] <= t0:
                jc += 1
                sc = lc[jc][1]
            if t1 > t0:
                out.append((t0, t1, sa, sb, sc))
                t0 = t1
        return out

    def _leg(self, x: int, d: float) -> list[tuple[float, int]]:
        """Change points ``(t, state)`` of leg ``x`` over the period, the first at t = 0."""
        T = self.T_s
        t_d = self.t_dead
        prof: tuple[tuple[float, int], ...]
        if d >= 1.0:
            prof = ((0.0, HIGH),)
        elif d <= 0.0:
            prof = ((0.0, LOW),)
        elif self._peak:
            prof = ((0.0, LOW), (0.5 * (1.0 - d) * T, HIGH), (0.5 * (1.0 + d) * T, LOW))
        else:
            prof = ((0.0, HIGH), (0.5 * d * T, LOW), (T - 0.5 * d * T, HIGH))
        tol = 1e-9 * T  # instants closer than this coincide (rounding of d T / 2 + t_dead)
        level = self._cmd[x]
        du = self._dead_end[x]  # end of the pending dead interval
        pts: list[tuple[float, int]] = [(0.0, DEAD if du > tol else level)]
        for e, new in prof:
            if new == level:
                continue
            if tol < du < e - tol:  # the pending dead interval ends before this edge
                pts.append((du, level))
            level = new
            if t_d > 0.0:
                du = e + t_d
                state = DEAD
            else:
                du = 0.0
                state = new
            if pts[-1][0] == e:
                pts[-1] = (e, state)
            else:
                pts.append((e, state))
        if tol < du < T - tol:
            pts.append((du, level))
            du = 0.0
        self._cmd[x] = level
        self._dead_end[x] = du - T if du > T + tol else 0.0
        return pts
