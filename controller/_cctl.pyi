"""Types of the binding of the controller core (controller/_cctl.c, controller/core/)."""

from typing import Any

KIND_TTDQ: int
KIND_TTAB: int
KIND_SFHF: int
KIND_SQW: int
KIND_SENSORED: int
KIND_HYB_TTDQ: int
KIND_HYB_SQW: int
KIND_SELF_DEMOD: int
KIND_EPF: int
KIND_EXTERNAL: int
CIC_MAX: int

def hypot(x: float, y: float) -> float: ...
def band_play(w_lo: float, w_mid: float, w_hi: float, h: float, y: float, w: float) -> float: ...
def band_weights(
    w_lo: float, w_mid: float, w_hi: float, h: float, y: float
) -> tuple[float, float]: ...
def smooth_sign(i_x: float, i_band: float, sine: bool) -> float: ...
def cross_saturation_offset(k_dq: float, i_q: float, L_d: float, L_q: float) -> float: ...
def svpwm(u_alpha: float, u_beta: float, u_dc: float) -> tuple[float, float, float]: ...
def limit_magnitude(x_1: float, x_2: float, x_max: float) -> tuple[float, float]: ...

# the public blocks (controller/_pi.py, ...): design values read-only, states writable
class Pi:
    @property
    def k_p(self) -> float: ...
    @property
    def k_i(self) -> float: ...
    @property
    def k_t(self) -> float: ...
    @property
    def T_s(self) -> float: ...
    u_i: float
    _e: float
    _u: float
    def __init__(self, k_p: float, k_i: float, T_s: float, k_t: float) -> None: ...
    def output(self, r: float, y: float, u_ff: float = 0.0) -> float: ...
    def update(self, u_lim: float) -> None: ...
    def reset(self, u_i: float = 0.0) -> None: ...

class Core:
    kind: int
    calls_python: int
    e_alpha: float
    e_beta: float
    mode: int
    w_m_ref: float
    w_m_hat: float
    i_d_ref: float
    i_q_ref: float
    tau_ref: float
    u_d: float
    u_q: float
    pi_d_u_i: float
    pi_q_u_i: float
    pi_w_u_i: float
    polarity_flip: int
    theta_hat: float
    w_hat: float
    err: float
    weight: float
    gain: float
    y: float
    hf_theta_hat: float
    hf_w_hat: float
    obs_theta_hat: float
    obs_w_hat: float
    sup_latched: int
    sup_detected_k: int
    def __init__(
        self,
        kind: int,
        measurement: type,
        measurement_slots: tuple[Any, ...],
        output: type,
        output_slots: tuple[Any, ...],
    ) -> None: ...
    def foc(
        self,
        n_p: float,
        L_d: float,
        L_q: float,
        psi_f: float,
        i_max: float,
        tau_max: float,
        t_delay: float,
        n_align: int,
        n_settle: int,
        theta0: float,
        raw: bool,
        align: bool,
    ) -> None: ...
    def pi(self, which: int, k_p: float, k_i: float, T_s: float, k_t: float) -> None: ...
    def speed_filter(self, b0: float, b1: float, a1: float) -> None: ...
    def polarity(self, L_d: float, T_s: float, i_pulse: float, u_frac: float) -> None: ...
    def rotating(
        self,
        V_h: float,
        wT: float,
        inv_norm: float,
        pll: tuple[float, float, float],
        bpf: tuple[float, float, float, float, float],
        lpf: tuple[float, float, float],
        hpf: tuple[float, float, float] | None,
        tracking: tuple[float, float, float, float] | None,
        quad: tuple[float, float, float, float, float] | None = None,
    ) -> None: ...
    def square_wave(
        self,
        cic: bool,
        M: int,
        U_h: float,
        t_comp: float,
        k_err: float,
        observer: tuple[float, float, float, float, float],
    ) -> None: ...
    def hybrid(
        self,
        observer: tuple[float, ...],
        band: tuple[float, float, float, float],
        T_s: float,
        n_p: float,
        J: float,
    ) -> None: ...
    def compensation(
        self,
        dead_time: tuple[float, float, float, float, float, bool, bool] | None,
        cross_saturation: tuple[float, bool] | None,
        offset_periods: int | None,
        hf_model: tuple[float, float] | None,
    ) -> None: ...
    def external(
        self, estimator: Any, estimator_input: type, estimator_input_slots: tuple[Any, ...]
    ) -> None: ...
    def external_c(self, address: int) -> None: ...
    def reference_model(self, alpha_s: float, n_p: float, a_max: float, T_s: float) -> None: ...
    def mechanical(
        self, T_s: float, g1: float, g2: float, g3: float, gt: float, l3: float
    ) -> None: ...
    def measured(self, floor: float) -> None: ...
    def accel_ff(self) -> None: ...
    def set_speed_ref(self, w_m_ref: float) -> None: ...
    def set_current_ref(self, i_dq: tuple[float, float] | None) -> None: ...
    def set_enable(self, enable: bool) -> None: ...
    def step(self, meas: Any) -> Any: ...
    def injection(self) -> tuple[float, float]: ...
    def supervision(self, *thresholds: float) -> None: ...
    def address(self) -> tuple[int, int]: ...

class Pll:
    @property
    def k_p(self) -> float: ...
    @property
    def k_i(self) -> float: ...
    @property
    def T_s(self) -> float: ...
    theta_hat: float
    w_hat: float
    w_i: float
    def __init__(self, k_p: float, k_i: float, T_s: float) -> None: ...
    def update(self, err: float, accel: float = 0.0) -> None: ...
    def reset(self, theta0: float, w0: float = 0.0) -> None: ...

class Polarity:
    @property
    def L_d(self) -> float: ...
    @property
    def T_s(self) -> float: ...
    @property
    def i_pulse(self) -> float: ...
    @property
    def u_frac(self) -> float: ...
    U: float
    N: int
    _n: int
    _i0: float
    _i1: float
    d_i_pos: float
    d_i_neg: float
    done: bool
    flip: bool
    def __init__(self, L_d: float, T_s: float, i_pulse: float, u_frac: float) -> None: ...
    def start(self, u_dc: float, i_d0: float) -> None: ...
    def step(self, i_d: float) -> float: ...

class Flux:
    @property
    def R_s(self) -> float: ...
    @property
    def zeta_f(self) -> float: ...
    @property
    def alpha_o(self) -> float: ...
    @property
    def L_d(self) -> float: ...
    @property
    def L_q(self) -> float: ...
    @property
    def psi_f(self) -> float: ...
    @property
    def T_s(self) -> float: ...
    @property
    def w_min(self) -> float: ...
    @property
    def k_p(self) -> float: ...
    @property
    def k_i(self) -> float: ...
    @property
    def _ki_T(self) -> float: ...
    @property
    def _zT(self) -> float: ...
    @property
    def _rT2(self) -> float: ...
    @property
    def _dL(self) -> float: ...
    psi_alpha: float
    psi_beta: float
    theta_hat: float
    w_hat: float
    eps: float
    accel: float
    _ia1: float
    _ib1: float
    _th_next: float
    _init: int
    def __init__(
        self,
        R_s: float,
        L_d: float,
        L_q: float,
        psi_f: float,
        T_s: float,
        zeta_f: float,
        w_min: float,
        k_p: float,
        k_i: float,
        alpha_o: float,
    ) -> None: ...
    def update(self, i_alpha: float, i_beta: float, u_alpha: float, u_beta: float) -> None: ...
    def update_slaved(
        self, i_alpha: float, i_beta: float, u_alpha: float, u_beta: float, theta: float, w: float
    ) -> None: ...
    def reset(self, theta0: float, w0: float = 0.0) -> None: ...
    def set_state(
        self, psi_alpha: float, psi_beta: float, i_alpha: float, i_beta: float
    ) -> None: ...

class Sup:
    latched: int
    detected_k: int
    def __init__(self, *thresholds: float) -> None: ...
    def _check(
        self,
        i_a: float,
        i_b: float,
        u_dc: float,
        d_a: float,
        d_b: float,
        d_c: float,
        enable: bool,
        mode: int,
        w_hat: float,
    ) -> int: ...
    def release_ok(self, u_dc: float) -> bool: ...
    def _reset_windows(self) -> None: ...
