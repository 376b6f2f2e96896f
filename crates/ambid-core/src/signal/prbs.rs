//! Pseudo-random binary sequences (maximum-length LFSR sequences).
//!
//! # Math
//! A linear feedback shift register of order $n$ over GF(2) produces the bit sequence
//! $$ a_{k+n} = \sum_{i=0}^{n-1} c_i\, a_{k+i} \pmod 2, $$
//! whose characteristic (feedback) polynomial is $p(x) = x^n + \sum_{i<n} c_i x^i$. From any non-zero
//! initial state the sequence is periodic with period equal to the order of $x$ modulo $p(x)$, which
//! is the maximum $L = 2^n - 1$ exactly when $p$ is *primitive*. Such an m-sequence
//! has $2^{n-1}$ ones and $2^{n-1}-1$ zeros per period; mapped to $\pm1$ (one $\mapsto +1$) its
//! circular autocorrelation is two-valued,
//! $$ R(\tau) = \frac1L \sum_{k=0}^{L-1} s_k s_{k+\tau} = \begin{cases} 1 & \tau \equiv 0 \pmod L \\
//! -1/L & \text{otherwise,}\end{cases} $$
//! i.e. that of white noise up to $-1/L$.
//!
//! Each bit is held for $N_b$ samples of $T_s$ and the period is repeated $N_p$ times, so (seed paper,
//! Section 3.1)
//! $$ T = N_p L N_b T_s,\qquad f_{\min} = \frac{1}{L N_b T_s},\qquad f_{\max} \approx \frac{1}{2 N_b T_s}. $$
//! The spectrum of one period has lines at multiples of $f_{\min}$ (the resolution) under a
//! $\operatorname{sinc}^2(f N_b T_s)$ envelope whose first zero is at $1/(N_b T_s)$; $f_{\max}$ is where
//! the envelope has dropped by about 4 dB. A larger $N_b$ concentrates energy at low frequency
//! (seed paper, Figure 4a); a larger $n$ gives denser lines at the cost of duration (Figure 4b).
//!
//! # Feedback taps
//! [`feedback_polynomial`] uses, for every order $2 \le n \le 31$, the maximal-length tap sets
//! tabulated in Xilinx application note XAPP052 (P. Alfke, "Efficient Shift Registers, LFSR Counters,
//! and Long Pseudo-Random Sequence Generators", 1996), also listed in Wikipedia's "Linear-feedback
//! shift register" article: taps $(n, t_1, t_2, \dots)$ stand for
//! $p(x) = x^n + x^{t_1} + x^{t_2} + \dots + 1$. The test suite proves each polynomial primitive
//! algebraically and runs the register over a full period for orders up to 22.
//!
//! # Example
//! ```
//! use ambid_core::signal::{prbs_period, PrbsSpec};
//! let s = prbs_period(5).unwrap();
//! assert_eq!(s.len(), 31);
//! assert_eq!(s.iter().map(|&b| b as i32).sum::<i32>(), 1); // one more +1 than -1
//!
//! let spec = PrbsSpec { order: 10, samples_per_bit: 5, periods: 20, amplitude: 0.2, offset: 0.0 };
//! let r = spec.report(50e-6).unwrap();
//! assert_eq!(r.period_samples, 5115);
//! assert!((r.duration_s - 5.115).abs() < 1e-12);
//! assert!((r.f_max_hz - 2000.0).abs() < 1e-9);
//! ```

use super::{
    check_count, check_positive, check_ts, repeat_period, total_samples, BandReport, Excitation,
    MAX_SAMPLES,
};
use crate::error::{Error, Result};

/// Smallest supported PRBS order.
pub const MIN_PRBS_ORDER: u32 = 2;
/// Largest supported PRBS order.
pub const MAX_PRBS_ORDER: u32 = 31;

/// Maximal-length taps from Xilinx XAPP052 (Alfke 1996), table "Taps for Maximum-Length LFSR
/// Counters", orders 2..=31 in order. Each entry lists the exponents of $p(x)$ other than the
/// constant term; the first is the order itself.
const TAPS: [&[u32]; 30] = [
    &[2, 1],
    &[3, 2],
    &[4, 3],
    &[5, 3],
    &[6, 5],
    &[7, 6],
    &[8, 6, 5, 4],
    &[9, 5],
    &[10, 7],
    &[11, 9],
    &[12, 6, 4, 1],
    &[13, 4, 3, 1],
    &[14, 5, 3, 1],
    &[15, 14],
    &[16, 15, 13, 4],
    &[17, 14],
    &[18, 11],
    &[19, 6, 2, 1],
    &[20, 17],
    &[21, 19],
    &[22, 21],
    &[23, 18],
    &[24, 23, 22, 17],
    &[25, 22],
    &[26, 6, 2, 1],
    &[27, 5, 2, 1],
    &[28, 25],
    &[29, 27],
    &[30, 6, 4, 1],
    &[31, 28],
];

fn check_order(order: u32) -> Result<()> {
    if (MIN_PRBS_ORDER..=MAX_PRBS_ORDER).contains(&order) {
        Ok(())
    } else {
        Err(Error::invalid(
            "order",
            format!(
                "PRBS order must be in {MIN_PRBS_ORDER}..={MAX_PRBS_ORDER}, got {order}; the period \
                 is 2^order - 1 bits (order 10 gives 1023)"
            ),
        ))
    }
}

/// The primitive feedback polynomial of order `order` as a bit mask: bit $i$ is the coefficient of
/// $x^i$ (bit `order` and bit 0 are always set). For example order 5 gives
/// $x^5 + x^3 + 1$ = `0b101001`.
///
/// # Errors
/// [`Error::InvalidArgument`] if `order` is outside `2..=31`.
///
/// # Example
/// ```
/// use ambid_core::signal::prbs::feedback_polynomial;
/// assert_eq!(feedback_polynomial(5).unwrap(), 0b10_1001);
/// ```
pub fn feedback_polynomial(order: u32) -> Result<u64> {
    check_order(order)?;
    let taps = TAPS[(order - MIN_PRBS_ORDER) as usize];
    Ok(taps.iter().fold(1u64, |m, &t| m | (1u64 << t)))
}

/// Period $L = 2^n - 1$ of the maximum-length sequence of order `order`.
///
/// # Errors
/// [`Error::InvalidArgument`] if `order` is outside `2..=31`.
pub fn prbs_length(order: u32) -> Result<usize> {
    check_order(order)?;
    Ok((1usize << order) - 1)
}

/// A Fibonacci linear feedback shift register producing a maximum-length sequence.
///
/// The register holds $a_k, \dots, a_{k+n-1}$ (bit 0 = $a_k$, the next output); each step outputs
/// $a_k$ and shifts in $a_{k+n} = \bigoplus_i c_i a_{k+i}$. It starts from the all-ones state, so
/// every period begins with $n$ ones. It is an endless iterator; use it to stream sequences too long
/// to hold in memory (orders above 28).
///
/// # Example
/// ```
/// use ambid_core::signal::Lfsr;
/// let mut r = Lfsr::new(3).unwrap();
/// let first: Vec<bool> = r.by_ref().take(7).collect();
/// let second: Vec<bool> = r.take(7).collect();
/// assert_eq!(first, second); // period 2^3 - 1 = 7
/// assert_eq!(first.iter().filter(|&&b| b).count(), 4);
/// ```
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Lfsr {
    state: u32,
    /// Feedback mask: bit $i$ is $c_i$ for $i < n$.
    mask: u32,
    order: u32,
}

impl Lfsr {
    /// A register of order `order` (2..=31) with the tabulated primitive polynomial, all-ones state.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if `order` is outside `2..=31`.
    pub fn new(order: u32) -> Result<Self> {
        let poly = feedback_polynomial(order)?;
        let low = (1u64 << order) - 1;
        Ok(Lfsr {
            state: low as u32,
            mask: (poly & low) as u32,
            order,
        })
    }

    /// The order $n$.
    pub fn order(&self) -> u32 {
        self.order
    }

    /// Current register contents (bit 0 is the next output bit).
    pub fn state(&self) -> u32 {
        self.state
    }

    /// Outputs the next bit and advances the register.
    #[inline]
    pub fn next_bit(&mut self) -> bool {
        let out = self.state & 1 == 1;
        let fb = (self.state & self.mask).count_ones() & 1;
        self.state = (self.state >> 1) | (fb << (self.order - 1));
        out
    }
}

impl Iterator for Lfsr {
    type Item = bool;
    fn next(&mut self) -> Option<bool> {
        Some(self.next_bit())
    }
}

/// One period ($L = 2^n - 1$ bits) of the maximum-length sequence of order `order`, as $\pm 1$
/// (a one bit maps to $+1$), starting from the all-ones register state.
///
/// # Errors
/// [`Error::InvalidArgument`] if `order` is outside `2..=31` or the period exceeds
/// [`MAX_SAMPLES`] (orders above 28; stream those with [`Lfsr`]).
///
/// # Example
/// ```
/// use ambid_core::signal::prbs_period;
/// assert_eq!(prbs_period(2).unwrap(), vec![1, 1, -1]);
/// ```
pub fn prbs_period(order: u32) -> Result<Vec<i8>> {
    let len = prbs_length(order)?;
    if len > MAX_SAMPLES {
        return Err(Error::invalid(
            "order",
            format!(
                "a PRBS period of order {order} has {len} bits, above the limit of {MAX_SAMPLES}; \
                 use an order <= 28 or stream the bits with Lfsr"
            ),
        ));
    }
    let mut r = Lfsr::new(order)?;
    Ok((0..len)
        .map(|_| if r.next_bit() { 1i8 } else { -1i8 })
        .collect())
}

/// A periodic PRBS excitation: order $n$, bit hold $N_b$, $N_p$ periods, levels
/// $\text{offset} \pm \text{amplitude}$.
///
/// # Requirements
/// `order` in `2..=31`; `samples_per_bit` $\ge 1$; `periods` $\ge 1$; `amplitude` finite and $> 0$;
/// `offset` finite; at most [`MAX_SAMPLES`] samples in total when generating.
///
/// # Example
/// ```
/// use ambid_core::signal::PrbsSpec;
/// let spec = PrbsSpec { order: 4, samples_per_bit: 2, periods: 3, amplitude: 0.5, offset: 0.1 };
/// let x = spec.generate(1e-3).unwrap();
/// assert_eq!((x.period_samples, x.periods, x.len()), (30, 3, 90));
/// assert!(x.values.iter().all(|&v| v == 0.6 || v == -0.4));
/// ```
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PrbsSpec {
    /// Register order $n$ (2..=31); the period is $L = 2^n - 1$ bits.
    pub order: u32,
    /// Samples per bit $N_b \ge 1$ (the bit time is $N_b T_s$).
    pub samples_per_bit: usize,
    /// Number of periods $N_p \ge 1$.
    pub periods: usize,
    /// Half the distance between the two levels ($> 0$).
    pub amplitude: f64,
    /// Mean of the two levels.
    pub offset: f64,
}

impl Default for PrbsSpec {
    /// The seed paper's design: $n = 10$, $N_b = 5$, $N_p = 20$, amplitude 1, no offset.
    fn default() -> Self {
        PrbsSpec {
            order: 10,
            samples_per_bit: 5,
            periods: 20,
            amplitude: 1.0,
            offset: 0.0,
        }
    }
}

impl PrbsSpec {
    fn validate(&self, ts: f64) -> Result<()> {
        check_ts(ts)?;
        check_order(self.order)?;
        check_count("samples_per_bit", self.samples_per_bit, 1)?;
        check_count("periods", self.periods, 1)?;
        check_positive("amplitude", self.amplitude)?;
        if !self.offset.is_finite() {
            return Err(Error::invalid(
                "offset",
                format!("must be finite, got {}", self.offset),
            ));
        }
        Ok(())
    }

    /// Samples per period $L N_b$, refused above [`MAX_SAMPLES`].
    fn period_samples(&self) -> Result<usize> {
        let len = prbs_length(self.order)?;
        match len.checked_mul(self.samples_per_bit) {
            Some(n) if n <= MAX_SAMPLES => Ok(n),
            _ => Err(Error::invalid(
                "samples_per_bit",
                format!(
                    "order {} with {} samples per bit gives more than {MAX_SAMPLES} samples per \
                     period; lower the order or samples_per_bit",
                    self.order, self.samples_per_bit
                ),
            )),
        }
    }

    /// Generates $N_p$ periods of $L N_b$ samples at sample time `ts` (seconds).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any field outside its range (see the type's requirements) or
    /// more than [`MAX_SAMPLES`] samples.
    pub fn generate(&self, ts: f64) -> Result<Excitation> {
        self.validate(ts)?;
        let period_samples = self.period_samples()?;
        total_samples(
            period_samples,
            self.periods,
            "lower the order, samples_per_bit or periods",
        )?;
        let hi = self.offset + self.amplitude;
        let lo = self.offset - self.amplitude;
        let mut period = Vec::with_capacity(period_samples);
        let mut r = Lfsr::new(self.order)?;
        let len = prbs_length(self.order)?;
        for _ in 0..len {
            let v = if r.next_bit() { hi } else { lo };
            period.extend(std::iter::repeat_n(v, self.samples_per_bit));
        }
        Ok(Excitation {
            values: repeat_period(&period, self.periods),
            ts,
            period_samples,
            periods: self.periods,
        })
    }

    /// Band, resolution, duration and level of the design, computed without generating it:
    /// $f_{\min} = \Delta f = 1/(L N_b T_s)$, $f_{\max} = 1/(2 N_b T_s)$, $T = N_p L N_b T_s$, and with
    /// $2^{n-1}$ samples at $o + a$ and $2^{n-1} - 1$ at $o - a$ per $L$ bits,
    /// $\mathrm{rms}^2 = \frac{(L+1)(o+a)^2 + (L-1)(o-a)^2}{2L}$.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for any field outside its range. Designs too long to generate can
    /// still be reported as long as the sample counts fit in `usize`.
    pub fn report(&self, ts: f64) -> Result<BandReport> {
        self.validate(ts)?;
        let len = prbs_length(self.order)?;
        let overflow = || {
            Error::invalid(
                "periods",
                "the total number of samples overflows; lower the order, samples_per_bit or periods",
            )
        };
        let period_samples = len.checked_mul(self.samples_per_bit).ok_or_else(overflow)?;
        let n_samples = period_samples
            .checked_mul(self.periods)
            .ok_or_else(overflow)?;
        let l = len as f64;
        let nb = self.samples_per_bit as f64;
        let (a, o) = (self.amplitude, self.offset);
        let ms = ((l + 1.0) * (o + a).powi(2) + (l - 1.0) * (o - a).powi(2)) / (2.0 * l);
        let rms = ms.sqrt();
        let peak = (o + a).abs().max((o - a).abs());
        let f_min = 1.0 / (l * nb * ts);
        Ok(BandReport {
            f_min_hz: f_min,
            f_max_hz: 1.0 / (2.0 * nb * ts),
            resolution_hz: f_min,
            duration_s: n_samples as f64 * ts,
            n_samples,
            period_samples,
            periods: self.periods,
            rms,
            peak,
            crest_factor: if rms > 0.0 { peak / rms } else { 0.0 },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_2_and_3_by_hand() {
        // x^2 + x + 1: a_{k+2} = a_k + a_{k+1}; from 1,1: 1,1,0,1,1,0,...
        assert_eq!(prbs_period(2).unwrap(), vec![1, 1, -1]);
        // x^3 + x^2 + 1: a_{k+3} = a_k + a_{k+2}; from 1,1,1: 1,1,1,0,1,0,0
        assert_eq!(prbs_period(3).unwrap(), vec![1, 1, 1, -1, 1, -1, -1]);
    }

    #[test]
    fn bad_orders_are_refused() {
        for o in [0, 1, 32, 64] {
            assert!(matches!(
                feedback_polynomial(o),
                Err(Error::InvalidArgument { name: "order", .. })
            ));
        }
        assert!(prbs_period(29).is_err());
    }
}
