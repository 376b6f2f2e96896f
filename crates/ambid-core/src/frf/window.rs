//! Spectral windows (tapers) for segment-averaged spectra, equal to `scipy.signal.get_window`.
//!
//! Every window here is a sum of cosines,
//! $$ w\[n\] = \sum_{m=0}^{M-1} a_m \cos(m\,\theta_n), \qquad
//!    \theta_n = -\pi + \frac{2\pi n}{L-1}, \quad n = 0, \dots, L-1, $$
//! with the coefficients $a_m$ of the table below. A **symmetric** window of length $n$ uses
//! $L = n$ (it is zero, or at its minimum, at both ends: filter design, one-off tapers). A
//! **periodic** (DFT-even) window of length $n$ is the symmetric window of length $L = n + 1$ without
//! its last sample: it is exactly one period of the cosine sum, which is what spectral analysis with
//! the DFT wants (scipy's `fftbins=True`, the default of `welch` and `csd`).
//!
//! | [`Window`] | $a_m$ | coherent gain | ENBW (bins) | highest side lobe |
//! |---|---|---|---|---|
//! | `Rectangular` | $1$ | $1$ | $1$ | $-13$ dB |
//! | `Hann` | $0.5,\ 0.5$ | $0.5$ | $1.5$ | $-31$ dB |
//! | `Hamming` | $0.54,\ 0.46$ | $0.54$ | $1.36$ | $-43$ dB |
//! | `Blackman` | $0.42,\ 0.5,\ 0.08$ | $0.42$ | $1.73$ | $-58$ dB |
//! | `FlatTop` | $0.21557895,\ 0.41663158,\ 0.277263158,\ 0.083578947,\ 0.006947368$ | $0.216$ | $3.77$ | $-93$ dB |
//!
//! (Gains and ENBW are those of the periodic windows; the symmetric ones differ by $O(1/n)$.)
//! The flat-top coefficients are scipy's 5-term set (D'Antona and Ferrero): the main lobe is flat to
//! about $0.01$ dB over $\pm\frac12$ bin, so a sinusoid's amplitude is read correctly wherever it falls
//! between bins, at the price of a wide main lobe.
//!
//! # Window figures of merit
//! For a window $w$ of length $n$ ([`WindowGains`]):
//! * sum $\sum_n w\[n\]$ and sum of squares $\sum_n w\[n\]^2$: the normalisations of the "spectrum" and
//!   "density" scalings in [`welch`](super::welch);
//! * coherent gain $\frac1n\sum_n w\[n\]$: the amplitude a windowed sinusoid at a bin frequency keeps;
//! * equivalent noise bandwidth $\mathrm{ENBW} = n \sum_n w\[n\]^2 / \left(\sum_n w\[n\]\right)^2$ bins,
//!   or $\mathrm{ENBW}\cdot f_s/n$ Hz: the width of the rectangular filter passing the same white-noise
//!   power as one DFT bin of the windowed data. A power spectrum ("spectrum" scaling) equals the
//!   density times $\mathrm{ENBW}$ in Hz.
//!
//! # Example
//! ```
//! use ambid_core::frf::window::{Window, WindowGains};
//! let w = Window::Hann.coefficients(4, true).unwrap();
//! let want = [0.0, 0.5, 1.0, 0.5];
//! assert!(w.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-15));
//! let g = WindowGains::of(&Window::Hann.coefficients(1024, true).unwrap()).unwrap();
//! assert!((g.coherent_gain() - 0.5).abs() < 1e-12 && (g.enbw_bins() - 1.5).abs() < 1e-12);
//! let w: Window = "flattop".parse().unwrap();
//! assert_eq!(w, Window::FlatTop);
//! ```

use crate::error::{check_finite, Error, Result};
use std::f64::consts::PI;
use std::fmt;
use std::str::FromStr;

/// A cosine-sum spectral window. See the [module documentation](self) for the coefficients.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Window {
    /// Rectangular (boxcar): no taper. Best resolution, worst leakage; exact for periodic signals
    /// analysed over whole periods.
    Rectangular,
    /// Hann (raised cosine): the usual default for random signals.
    Hann,
    /// Hamming: lower first side lobe than Hann, slower side-lobe decay.
    Hamming,
    /// Blackman (3-term): low leakage, wider main lobe.
    Blackman,
    /// Flat top (5-term, scipy's coefficients): accurate amplitudes of sinusoids between bins.
    FlatTop,
}

const RECTANGULAR: [f64; 1] = [1.0];
const HANN: [f64; 2] = [0.5, 0.5];
const HAMMING: [f64; 2] = [0.54, 0.46];
const BLACKMAN: [f64; 3] = [0.42, 0.50, 0.08];
const FLAT_TOP: [f64; 5] = [
    0.21557895,
    0.41663158,
    0.277263158,
    0.083578947,
    0.006947368,
];

impl Window {
    /// All windows, in the order of the enum.
    pub const ALL: [Window; 5] = [
        Window::Rectangular,
        Window::Hann,
        Window::Hamming,
        Window::Blackman,
        Window::FlatTop,
    ];

    /// The short name accepted by [`FromStr`] and printed by [`Display`](fmt::Display):
    /// `rect`, `hann`, `hamming`, `blackman`, `flattop`.
    pub fn name(self) -> &'static str {
        match self {
            Window::Rectangular => "rect",
            Window::Hann => "hann",
            Window::Hamming => "hamming",
            Window::Blackman => "blackman",
            Window::FlatTop => "flattop",
        }
    }

    /// The cosine-sum coefficients $a_0, a_1, \dots$ (in the convention $\theta \in \[-\pi, \pi\]$ of
    /// the module documentation).
    pub fn cosine_terms(self) -> &'static [f64] {
        match self {
            Window::Rectangular => &RECTANGULAR,
            Window::Hann => &HANN,
            Window::Hamming => &HAMMING,
            Window::Blackman => &BLACKMAN,
            Window::FlatTop => &FLAT_TOP,
        }
    }

    /// The `n` window coefficients, periodic (DFT-even, for spectral analysis) or symmetric; equal to
    /// `scipy.signal.get_window(name, n, fftbins=periodic)`. A window of length 1 is `[1.0]`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `n = 0`.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::window::Window;
    /// let sym = Window::Hamming.coefficients(3, false).unwrap();
    /// assert!((sym[0] - 0.08).abs() < 1e-15 && (sym[1] - 1.0).abs() < 1e-15);
    /// let per = Window::Hamming.coefficients(2, true).unwrap();
    /// assert!((per[0] - 0.08).abs() < 1e-15 && (per[1] - 1.0).abs() < 1e-15);
    /// assert!(Window::Hann.coefficients(0, true).is_err());
    /// ```
    pub fn coefficients(self, n: usize, periodic: bool) -> Result<Vec<f64>> {
        if n == 0 {
            return Err(Error::invalid(
                "n",
                "a window needs at least one sample; pass n ≥ 1",
            ));
        }
        if n == 1 {
            return Ok(vec![1.0]);
        }
        // symmetric window of length `len`, truncated to `n` when periodic
        let len = if periodic { n + 1 } else { n };
        let terms = self.cosine_terms();
        let step = 2.0 * PI / (len - 1) as f64;
        let w = (0..n)
            .map(|i| {
                // numpy.linspace(-π, π, len): start + i·step, the last point exactly π
                let theta = if i == len - 1 {
                    PI
                } else {
                    i as f64 * step - PI
                };
                terms
                    .iter()
                    .enumerate()
                    .fold(0.0, |acc, (m, a)| acc + a * (m as f64 * theta).cos())
            })
            .collect();
        Ok(w)
    }
}

impl fmt::Display for Window {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Window {
    type Err = Error;

    /// Parses `rect` / `rectangular` / `boxcar`, `hann`, `hamming`, `blackman`, `flattop`
    /// (case-insensitive, surrounding blanks ignored).
    fn from_str(s: &str) -> Result<Self> {
        match s.trim().to_ascii_lowercase().as_str() {
            "rect" | "rectangular" | "boxcar" => Ok(Window::Rectangular),
            "hann" => Ok(Window::Hann),
            "hamming" => Ok(Window::Hamming),
            "blackman" => Ok(Window::Blackman),
            "flattop" => Ok(Window::FlatTop),
            other => Err(Error::invalid(
                "window",
                format!(
                    "unknown window `{other}`; use one of rect, hann, hamming, blackman, flattop"
                ),
            )),
        }
    }
}

/// Sums of a window that set the scaling of spectra, and the figures of merit derived from them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowGains {
    /// Number of coefficients $n$.
    pub n: usize,
    /// $\sum_n w\[n\]$.
    pub sum: f64,
    /// $\sum_n w\[n\]^2$.
    pub sum_sq: f64,
}

impl WindowGains {
    /// The sums of the coefficients `w`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an empty window or one whose sum is not positive (the
    /// normalisations divide by it); [`Error::NonFinite`] for NaN or infinite coefficients.
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::window::WindowGains;
    /// let g = WindowGains::of(&[1.0, 1.0, 1.0, 1.0]).unwrap();
    /// assert_eq!((g.sum, g.sum_sq, g.coherent_gain(), g.enbw_bins()), (4.0, 4.0, 1.0, 1.0));
    /// assert_eq!(g.enbw_hz(1000.0), 250.0);
    /// ```
    pub fn of(w: &[f64]) -> Result<Self> {
        if w.is_empty() {
            return Err(Error::invalid(
                "w",
                "the window is empty; pass at least one coefficient",
            ));
        }
        check_finite("w", w)?;
        let sum: f64 = w.iter().sum();
        let sum_sq: f64 = w.iter().map(|v| v * v).sum();
        if sum <= 0.0 {
            return Err(Error::invalid(
                "w",
                format!("the window's coefficients sum to {sum}; a spectral window must have a positive sum"),
            ));
        }
        Ok(Self {
            n: w.len(),
            sum,
            sum_sq,
        })
    }

    /// Coherent gain $\frac1n \sum_n w\[n\]$.
    pub fn coherent_gain(&self) -> f64 {
        self.sum / self.n as f64
    }

    /// Equivalent noise bandwidth in bins, $n \sum w^2 / (\sum w)^2$.
    pub fn enbw_bins(&self) -> f64 {
        self.n as f64 * self.sum_sq / (self.sum * self.sum)
    }

    /// Equivalent noise bandwidth in Hz at the sampling frequency `fs` (Hz): $\mathrm{ENBW}\cdot f_s/n$.
    pub fn enbw_hz(&self, fs: f64) -> f64 {
        self.enbw_bins() * fs / self.n as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn periodic_is_truncated_symmetric() {
        for w in Window::ALL {
            for n in [2, 3, 8, 17] {
                let p = w.coefficients(n, true).unwrap();
                let s = w.coefficients(n + 1, false).unwrap();
                assert_eq!(p[..], s[..n], "{w} {n}");
            }
        }
    }

    #[test]
    fn symmetric_windows_are_symmetric_and_peak_at_one() {
        for w in Window::ALL {
            let c = w.coefficients(33, false).unwrap();
            for i in 0..33 {
                assert!((c[i] - c[32 - i]).abs() < 1e-15, "{w}");
            }
            assert!((c[16] - 1.0).abs() < 1e-8, "{w}: {}", c[16]);
        }
    }

    #[test]
    fn names_round_trip() {
        for w in Window::ALL {
            assert_eq!(w.name().parse::<Window>().unwrap(), w);
            assert_eq!(w.to_string().to_uppercase().parse::<Window>().unwrap(), w);
        }
        assert_eq!(
            " Rectangular ".parse::<Window>().unwrap(),
            Window::Rectangular
        );
        let e = "kaiser".parse::<Window>().unwrap_err();
        assert!(e.to_string().contains("kaiser"), "{e}");
    }

    #[test]
    fn gains_of_periodic_windows() {
        let n = 4096;
        let cases = [
            (Window::Rectangular, 1.0, 1.0),
            (Window::Hann, 0.5, 1.5),
            // Hamming: (0.54² + 0.46²/2) / 0.54²
            (
                Window::Hamming,
                0.54,
                (0.54f64.powi(2) + 0.46f64.powi(2) / 2.0) / 0.2916,
            ),
            (
                Window::Blackman,
                0.42,
                (0.42f64.powi(2) + (0.25 + 0.0064) / 2.0) / 0.42f64.powi(2),
            ),
        ];
        for (w, cg, enbw) in cases {
            let g = WindowGains::of(&w.coefficients(n, true).unwrap()).unwrap();
            assert!((g.coherent_gain() - cg).abs() < 1e-12, "{w}");
            assert!((g.enbw_bins() - enbw).abs() < 1e-12, "{w}");
        }
        let g = WindowGains::of(&Window::FlatTop.coefficients(n, true).unwrap()).unwrap();
        assert!((g.coherent_gain() - 0.21557895).abs() < 1e-12);
        assert!((g.enbw_bins() - 3.7702).abs() < 1e-3, "{}", g.enbw_bins());
    }

    #[test]
    fn bad_gains() {
        assert!(WindowGains::of(&[]).is_err());
        assert!(WindowGains::of(&[0.0, 0.0]).is_err());
        assert!(matches!(
            WindowGains::of(&[1.0, f64::NAN]),
            Err(Error::NonFinite { index: 1, .. })
        ));
    }
}
