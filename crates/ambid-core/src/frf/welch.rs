//! Welch-averaged auto and cross spectra of several channels at once, streaming, with H1/H2
//! frequency-response estimates and coherence; a single-record empirical transfer-function estimate
//! ([`etfe`]).
//!
//! The numbers equal scipy's `signal.welch`, `signal.csd` and `signal.coherence` (one-sided, mean
//! average, no zero padding) to rounding; `tests/frf_welch.rs` checks this against fixtures.
//!
//! # The estimator
//! A record $x_i\[n\]$, $n = 0, \dots, N-1$, of channel $i$ is cut into $K$ segments of length $L$
//! (`nperseg`) that overlap by $L - S$ samples (`noverlap`; the step is $S$):
//! $$ x_i^{(p)}\[n\] = x_i\[pS + n\], \qquad n = 0, \dots, L-1, \qquad
//!    p = 0, \dots, K-1, \qquad K = \left\lfloor \frac{N - (L - S)}{S} \right\rfloor . $$
//! The first segment starts at sample 0; samples after the last whole segment are not used. Each
//! segment is detrended ($d_i^{(p)} = x_i^{(p)}$ minus nothing, its mean, or its least-squares line,
//! [`SegmentDetrend`]), multiplied by the window $w$ and transformed:
//! $$ X_i^{(p)}(k) = \sum_{n=0}^{L-1} w\[n\]\, d_i^{(p)}\[n\]\, e^{-j 2\pi k n / L}, \qquad
//!    f_k = \frac{k f_s}{L}, \quad k = 0, \dots, \lfloor L/2 \rfloor . $$
//! The one-sided cross spectrum averages the segment cross periodograms:
//! $$ S_{ij}(f_k) = \frac{c_k\, s}{K} \sum_{p=0}^{K-1} \overline{X_i^{(p)}(k)}\, X_j^{(p)}(k),
//!    \qquad c_k = \begin{cases} 1 & k = 0 \text{ or } k = L/2 \ (L \text{ even}) \\ 2 &
//!    \text{otherwise,} \end{cases} $$
//! so $S_{ji} = \overline{S_{ij}}$, $S_{ii} \ge 0$ is real, and $S_{ij}$ is scipy's `csd(x_i, x_j)`.
//! The factor $c_k$ folds the negative frequencies onto the positive ones (the DC and Nyquist lines
//! have no mirror image). The window normalisation $s$ ([`Scaling`]) is
//! * **density** $s = 1 / (f_s \sum_n w\[n\]^2)$, units²/Hz: for white noise of variance $\sigma^2$,
//!   $\mathrm E\,|X(k)|^2 = \sigma^2 \sum w^2$, so $S_{ii} = 2\sigma^2/f_s$ and
//!   $\sum_k S_{ii}(f_k)\, \Delta f \approx \sigma^2$ with $\Delta f = f_s / L$ (Parseval);
//! * **spectrum** $s = 1 / (\sum_n w\[n\])^2$, units²: a sinusoid $a\cos(2\pi f_k t)$ at a line gives
//!   $|X(k)| = \frac a2 \sum w$, so $S_{ii}(f_k) = a^2/2$, its mean square. The two differ by the
//!   window's equivalent noise bandwidth in Hz ([`WindowGains::enbw_hz`]).
//!
//! # Frequency responses and coherence
//! With input channel $u$ and output channel $y$ ([`CrossSpectra::h1`], [`CrossSpectra::h2`],
//! [`CrossSpectra::coherence`]):
//! $$ H_1 = \frac{S_{uy}}{S_{uu}}, \qquad H_2 = \frac{S_{yy}}{S_{yu}}, \qquad
//!    \gamma^2_{uy} = \frac{|S_{uy}|^2}{S_{uu} S_{yy}} = \frac{H_1}{H_2} \in \[0, 1\]. $$
//! $H_1$ is unbiased when the noise is on the output only, $H_2$ when it is on the input only; the
//! true response lies between them in magnitude. **In closed loop** the plant input $u$ is correlated
//! with the output noise through the controller, so $H_1$ from $u$ to $y$ is biased towards
//! $-1/C$; use the external excitation $r$ as the reference ($T_{ry} = S_{ry}/S_{rr}$,
//! $S = T_{ru} = S_{ru}/S_{rr}$, $P = S_{ry}/S_{ru}$), see [`closed_loop`](super::closed_loop).
//!
//! With $n_d$ independent averages and Gaussian data (Bendat and Piersol, *Random Data*, §9.2),
//! $$ \operatorname{Var} |\hat H_1| \approx \frac{1-\gamma^2}{2 n_d \gamma^2} |H|^2, \qquad
//!    \operatorname{Var} \arg \hat H_1 \approx \frac{1-\gamma^2}{2 n_d \gamma^2}, \qquad
//!    \mathrm E\,|\hat H_1 - H|^2 \approx \frac{1-\gamma^2}{n_d \gamma^2} |H|^2
//!    = \frac{(1-\gamma^2)\, S_{yy}}{n_d\, S_{uu}} $$
//! ([`CrossSpectra::h1_variance`], with $n_d$ the effective number of averages below). The coherence
//! estimate is biased upwards for few averages: uncorrelated channels show
//! $\mathrm E\,\hat\gamma^2 \approx 1/n_d$, and a single segment always gives $\hat\gamma^2 = 1$.
//!
//! Overlapping segments are not independent. For a smooth spectrum, Welch (1967) gives the variance
//! of the averaged periodogram as $S^2 / n_{\text{eff}}$ with
//! $$ n_{\text{eff}} = \frac{K}{1 + 2 \sum_{l=1}^{K-1} \left(1 - \frac lK\right) \rho_l^2}, \qquad
//!    \rho_l = \frac{\sum_n w\[n\]\, w\[n + lS\]}{\sum_n w\[n\]^2} $$
//! ([`CrossSpectra::effective_averages`]); Hann with 50 % overlap has $\rho_1 = 1/6$, so
//! $n_{\text{eff}} \approx K / 1.056$.
//!
//! # Streaming, complexity and memory
//! [`WelchAccumulator`] takes the record in chunks of any length and keeps only a ring of the last
//! $L$ samples per channel, the spectra of the current segment and the running sums
//! $\sum_p \overline{X_i^{(p)}} X_j^{(p)}$ for $i \le j$: memory $O(C^2 L)$ for $C$ channels,
//! independent of $N$. One real-FFT plan (realfft) and its scratch buffers are made once; processing a
//! segment allocates nothing. Work is $O\!\left(\frac{N}{S}\,(C\, L\log L + C^2 L)\right)$, i.e.
//! $O(C N \log L + C^2 N)$ at the default 50 % overlap. The result does not depend on how the record
//! is chunked (it is bit-identical).
//!
//! # Differences from scipy
//! scipy silently shrinks `nperseg` to the record length and zero-pads the shorter of two records;
//! here both are errors. Zero padding (`nfft`), two-sided spectra and the median average are not
//! offered.
//!
//! # Example
//! ```
//! use ambid_core::frf::welch::{welch_spectra, WelchOptions};
//! use ambid_core::signal::{Distribution, NoiseSpec};
//! use std::f64::consts::PI;
//! let fs = 1000.0;
//! let u = NoiseSpec { distribution: Distribution::Gaussian, rms: 1.0, n_samples: 8192,
//!                     band_hz: None, seed: 7 }.generate(1.0 / fs).unwrap().values;
//! // y[n] = 0.5 u[n] + 0.25 u[n-1]: G(f) = 0.5 + 0.25 e^{-j2πf/fs}
//! let y: Vec<f64> = (0..u.len()).map(|n| 0.5 * u[n] + if n > 0 { 0.25 * u[n - 1] } else { 0.0 }).collect();
//! let s = welch_spectra(&[&u, &y], &WelchOptions::new(fs, 256)).unwrap();
//! assert_eq!(s.n_segments(), 63);
//! let (h, c) = (s.h1(0, 1).unwrap(), s.coherence(0, 1).unwrap());
//! for k in 1..s.f_hz().len() - 1 {
//!     let g = 0.5 + 0.25 * num_complex::Complex::from_polar(1.0, -2.0 * PI * s.f_hz()[k] / fs);
//!     assert!((h[k] - g).norm() < 0.02 * g.norm() && c[k] > 0.99);
//! }
//! ```

use super::window::{Window, WindowGains};
use crate::c64;
use crate::error::{check_finite, Error, Result};
use realfft::{RealFftPlanner, RealToComplex};
use std::fmt;
use std::sync::Arc;

/// What is removed from each segment before it is windowed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SegmentDetrend {
    /// Nothing (scipy `detrend=False`).
    None,
    /// The segment mean (scipy `detrend='constant'`, the default).
    #[default]
    Constant,
    /// The least-squares straight line through the segment (scipy `detrend='linear'`).
    Linear,
}

/// Normalisation of the spectra; see the [module documentation](self).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Scaling {
    /// Spectral density, units²/Hz: $s = 1/(f_s \sum w^2)$ (scipy `scaling='density'`, the default).
    #[default]
    Density,
    /// Power spectrum, units²: $s = 1/(\sum w)^2$ (scipy `scaling='spectrum'`).
    Spectrum,
}

/// Settings of a Welch estimate. Build with [`WelchOptions::new`] and change fields with struct
/// update syntax; everything is checked by [`WelchOptions::validate`] when it is used.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WelchOptions {
    /// Sampling frequency in Hz.
    pub fs: f64,
    /// Segment length $L$ in samples ($\ge 2$); the frequency resolution is $f_s / L$.
    pub nperseg: usize,
    /// Samples shared by consecutive segments ($< L$); the step is $L -$ `noverlap`.
    pub noverlap: usize,
    /// Window applied to each segment (periodic, as scipy's default `fftbins=True`).
    pub window: Window,
    /// Trend removed from each segment before windowing.
    pub detrend: SegmentDetrend,
    /// Density (units²/Hz) or power spectrum (units²).
    pub scaling: Scaling,
}

impl WelchOptions {
    /// scipy's defaults: periodic Hann window, `noverlap = nperseg / 2`, constant detrend, density
    /// scaling (one-sided, mean average).
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::welch::{Scaling, SegmentDetrend, WelchOptions};
    /// use ambid_core::frf::window::Window;
    /// let o = WelchOptions::new(20e3, 1024);
    /// assert_eq!((o.noverlap, o.window, o.detrend, o.scaling),
    ///            (512, Window::Hann, SegmentDetrend::Constant, Scaling::Density));
    /// assert!(o.validate().is_ok());
    /// assert!(WelchOptions::new(0.0, 1024).validate().is_err());
    /// ```
    pub fn new(fs: f64, nperseg: usize) -> Self {
        Self {
            fs,
            nperseg,
            noverlap: nperseg / 2,
            window: Window::Hann,
            detrend: SegmentDetrend::Constant,
            scaling: Scaling::Density,
        }
    }

    /// Checks the settings: `fs` finite and $> 0$, `nperseg` $\ge 2$, `noverlap` $<$ `nperseg`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the offending field.
    pub fn validate(&self) -> Result<()> {
        if !(self.fs.is_finite() && self.fs > 0.0) {
            return Err(Error::invalid(
                "fs",
                format!(
                    "the sampling frequency must be a finite number of Hz > 0, got {}",
                    self.fs
                ),
            ));
        }
        if self.nperseg < 2 {
            return Err(Error::invalid(
                "nperseg",
                format!(
                    "a segment needs at least 2 samples, got {}; raise nperseg",
                    self.nperseg
                ),
            ));
        }
        if self.noverlap >= self.nperseg {
            return Err(Error::invalid(
                "noverlap",
                format!(
                    "the overlap must be smaller than the segment length nperseg = {}, got {}; \
                     lower noverlap (nperseg / 2 is the usual choice)",
                    self.nperseg, self.noverlap
                ),
            ));
        }
        Ok(())
    }

    /// The step between segment starts, `nperseg - noverlap` (0 if the options are invalid).
    pub fn step(&self) -> usize {
        self.nperseg.saturating_sub(self.noverlap)
    }

    /// Number of whole segments in a record of `n_samples`:
    /// $\lfloor (N - \text{noverlap}) / S \rfloor$ for $N \ge L$, else 0 (0 if the options are
    /// invalid).
    ///
    /// # Example
    /// ```
    /// use ambid_core::frf::welch::WelchOptions;
    /// let o = WelchOptions::new(1.0, 256);
    /// assert_eq!((o.n_segments(255), o.n_segments(256), o.n_segments(383), o.n_segments(384)), (0, 1, 1, 2));
    /// ```
    pub fn n_segments(&self, n_samples: usize) -> usize {
        let step = self.step();
        if step == 0 || n_samples < self.nperseg {
            0
        } else {
            (n_samples - self.noverlap) / step
        }
    }

    /// The one-sided frequency grid $f_k = k f_s / L$, $k = 0, \dots, \lfloor L/2 \rfloor$, in Hz.
    pub fn frequencies(&self) -> Vec<f64> {
        let n = self.nperseg as f64;
        (0..=self.nperseg / 2)
            .map(|k| k as f64 * self.fs / n)
            .collect()
    }

    /// The error for a record of `n_samples` too short to hold one segment.
    pub fn too_short(&self, n_samples: usize) -> Error {
        Error::invalid(
            "nperseg",
            format!(
                "record has {n_samples} samples, nperseg is {}: lower nperseg (or pass a longer \
                 record) so that at least one whole segment fits",
                self.nperseg
            ),
        )
    }
}

/// Names for non-finite errors in multi-channel input (the error type holds a `&'static str`).
const CHANNEL_NAMES: [&str; 16] = [
    "channel 0",
    "channel 1",
    "channel 2",
    "channel 3",
    "channel 4",
    "channel 5",
    "channel 6",
    "channel 7",
    "channel 8",
    "channel 9",
    "channel 10",
    "channel 11",
    "channel 12",
    "channel 13",
    "channel 14",
    "channel 15",
];

fn channel_name(c: usize) -> &'static str {
    CHANNEL_NAMES.get(c).copied().unwrap_or("a channel ≥ 16")
}

/// Streaming Welch estimator of all auto and cross spectra of `n_channels` channels.
///
/// Push the record in chunks (any lengths, including 0; every channel the same length per chunk)
/// and call [`finish`](Self::finish) at any time. Holds $O(C^2 L)$ numbers, never the record; see
/// the [module documentation](self).
///
/// # Example
/// ```
/// use ambid_core::frf::welch::{welch_spectra, WelchAccumulator, WelchOptions};
/// let x: Vec<f64> = (0..1000).map(|k| (0.3 * k as f64).sin() + 0.01 * (k % 7) as f64).collect();
/// let y: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
/// let opts = WelchOptions::new(100.0, 128);
/// let mut acc = WelchAccumulator::new(2, &opts).unwrap();
/// for (a, b) in x.chunks(300).zip(y.chunks(300)) {
///     acc.push(&[a, b]).unwrap();
/// }
/// let streamed = acc.finish().unwrap();
/// let one_shot = welch_spectra(&[&x, &y], &opts).unwrap();
/// assert_eq!(streamed, one_shot);
/// assert_eq!(streamed.n_segments(), 14);
/// ```
#[derive(Clone)]
pub struct WelchAccumulator {
    opts: WelchOptions,
    n_channels: usize,
    n_freq: usize,
    window: Vec<f64>,
    gains: WindowGains,
    /// $\rho_l^2$ for $l = 1, 2, \dots$ while $lS < L$.
    overlap_corr_sq: Vec<f64>,
    fft: Arc<dyn RealToComplex<f64>>,
    /// Channel-major rings of the last `nperseg` samples.
    ring: Vec<f64>,
    /// Next write position in every ring (= oldest sample once the ring is full).
    head: usize,
    /// Samples of the current segment already in the ring.
    filled: usize,
    /// Segment buffer: detrended, windowed, then destroyed by the FFT.
    seg: Vec<f64>,
    scratch: Vec<c64>,
    /// Channel-major spectra of the current segment.
    spec: Vec<c64>,
    /// Pair-major running sums of $\overline{X_i} X_j$, $i \le j$.
    sums: Vec<c64>,
    n_samples: usize,
    n_segments: usize,
}

impl fmt::Debug for WelchAccumulator {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("WelchAccumulator")
            .field("opts", &self.opts)
            .field("n_channels", &self.n_channels)
            .field("n_samples", &self.n_samples)
            .field("n_segments", &self.n_segments)
            .finish_non_exhaustive()
    }
}

impl WelchAccumulator {
    /// An empty accumulator for `n_channels` channels.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for `n_channels = 0` or invalid options
    /// ([`WelchOptions::validate`]).
    pub fn new(n_channels: usize, opts: &WelchOptions) -> Result<Self> {
        opts.validate()?;
        if n_channels == 0 {
            return Err(Error::invalid(
                "n_channels",
                "at least one channel is needed; pass n_channels ≥ 1",
            ));
        }
        let l = opts.nperseg;
        let n_freq = l / 2 + 1;
        let window = opts.window.coefficients(l, true)?;
        let gains = WindowGains::of(&window)?;
        let overlap_corr_sq = overlap_correlation_sq(&window, opts.step())?;
        let fft = RealFftPlanner::<f64>::new().plan_fft_forward(l);
        let scratch = fft.make_scratch_vec();
        let n_pairs = n_channels * (n_channels + 1) / 2;
        Ok(Self {
            opts: *opts,
            n_channels,
            n_freq,
            window,
            gains,
            overlap_corr_sq,
            fft,
            ring: vec![0.0; n_channels * l],
            head: 0,
            filled: 0,
            seg: vec![0.0; l],
            scratch,
            spec: vec![c64::new(0.0, 0.0); n_channels * n_freq],
            sums: vec![c64::new(0.0, 0.0); n_pairs * n_freq],
            n_samples: 0,
            n_segments: 0,
        })
    }

    /// Appends the next `chunk[c].len()` samples of every channel `c` (all the same length, any
    /// length) and processes every segment they complete.
    ///
    /// # Errors
    /// [`Error::DimensionMismatch`] if `chunk` does not hold one slice per channel or the slices
    /// differ in length; [`Error::NonFinite`] for a NaN or infinite sample, with its index counted
    /// from the start of the record (what = `"channel c"`). On error nothing is consumed and the
    /// accumulator is unchanged.
    pub fn push<S: AsRef<[f64]>>(&mut self, chunk: &[S]) -> Result<()> {
        if chunk.len() != self.n_channels {
            return Err(Error::DimensionMismatch {
                context: "WelchAccumulator::push (one slice per channel)",
                expected: format!("{} channels", self.n_channels),
                got: format!("{} slices", chunk.len()),
            });
        }
        let len = chunk[0].as_ref().len();
        for (c, x) in chunk.iter().enumerate() {
            let x = x.as_ref();
            if x.len() != len {
                return Err(Error::DimensionMismatch {
                    context: "WelchAccumulator::push (every channel's chunk the same length)",
                    expected: format!("{len} samples (channel 0)"),
                    got: format!("{} samples in channel {c}", x.len()),
                });
            }
            if let Some(i) = x.iter().position(|v| !v.is_finite()) {
                return Err(Error::NonFinite {
                    what: channel_name(c),
                    index: self.n_samples + i,
                });
            }
        }
        let l = self.opts.nperseg;
        let mut pos = 0;
        while pos < len {
            let take = (len - pos).min(l - self.filled);
            let first = take.min(l - self.head);
            for (c, x) in chunk.iter().enumerate() {
                let x = &x.as_ref()[pos..pos + take];
                let ring = &mut self.ring[c * l..(c + 1) * l];
                ring[self.head..self.head + first].copy_from_slice(&x[..first]);
                ring[..take - first].copy_from_slice(&x[first..]);
            }
            self.head = (self.head + take) % l;
            self.filled += take;
            pos += take;
            if self.filled == l {
                self.process_segment()?;
                self.filled = self.opts.noverlap;
            }
        }
        self.n_samples += len;
        Ok(())
    }

    /// Detrends, windows and transforms the full ring of every channel, and adds the products.
    fn process_segment(&mut self) -> Result<()> {
        let l = self.opts.nperseg;
        let nf = self.n_freq;
        let head = self.head;
        for c in 0..self.n_channels {
            let ring = &self.ring[c * l..(c + 1) * l];
            self.seg[..l - head].copy_from_slice(&ring[head..]);
            self.seg[l - head..].copy_from_slice(&ring[..head]);
            detrend_and_window(&mut self.seg, &self.window, self.opts.detrend);
            self.fft
                .process_with_scratch(
                    &mut self.seg,
                    &mut self.spec[c * nf..(c + 1) * nf],
                    &mut self.scratch,
                )
                .map_err(|e| Error::numerical("Welch segment FFT", e.to_string()))?;
        }
        let mut pair = 0;
        for i in 0..self.n_channels {
            let xi = &self.spec[i * nf..(i + 1) * nf];
            for j in i..self.n_channels {
                let acc = &mut self.sums[pair * nf..(pair + 1) * nf];
                if i == j {
                    for (a, x) in acc.iter_mut().zip(xi) {
                        a.re += x.norm_sqr();
                    }
                } else {
                    let xj = &self.spec[j * nf..(j + 1) * nf];
                    for ((a, x), y) in acc.iter_mut().zip(xi).zip(xj) {
                        *a += x.conj() * y;
                    }
                }
                pair += 1;
            }
        }
        self.n_segments += 1;
        Ok(())
    }

    /// The averaged spectra of everything pushed so far (the accumulator can go on taking data).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] if not one whole segment has been pushed yet ("record has N
    /// samples, nperseg is M: lower nperseg").
    pub fn finish(&self) -> Result<CrossSpectra> {
        if self.n_segments == 0 {
            return Err(self.opts.too_short(self.n_samples));
        }
        let nc = self.n_channels;
        let nf = self.n_freq;
        let k = self.n_segments;
        let s = match self.opts.scaling {
            Scaling::Density => 1.0 / (self.opts.fs * self.gains.sum_sq),
            Scaling::Spectrum => 1.0 / (self.gains.sum * self.gains.sum),
        } / k as f64;
        let even = self.opts.nperseg % 2 == 0;
        let fold = |f: usize| {
            if f == 0 || (even && f == nf - 1) {
                s
            } else {
                2.0 * s
            }
        };
        let mut data = vec![c64::new(0.0, 0.0); nc * nc * nf];
        let mut pair = 0;
        for i in 0..nc {
            for j in i..nc {
                let sum = &self.sums[pair * nf..(pair + 1) * nf];
                for (f, z) in sum.iter().enumerate() {
                    let v = z * fold(f);
                    data[(i * nc + j) * nf + f] = v;
                    data[(j * nc + i) * nf + f] = v.conj();
                }
                pair += 1;
            }
        }
        let sum_rho: f64 = self
            .overlap_corr_sq
            .iter()
            .enumerate()
            .take(k - 1)
            .map(|(m, r2)| (1.0 - (m + 1) as f64 / k as f64) * r2)
            .sum();
        Ok(CrossSpectra {
            opts: self.opts,
            f_hz: self.opts.frequencies(),
            n_channels: nc,
            n_samples: self.n_samples,
            n_segments: k,
            effective_averages: k as f64 / (1.0 + 2.0 * sum_rho),
            data,
        })
    }

    /// Number of channels.
    pub fn n_channels(&self) -> usize {
        self.n_channels
    }

    /// Samples per channel pushed so far.
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// Whole segments processed so far.
    pub fn n_segments(&self) -> usize {
        self.n_segments
    }

    /// The options in use.
    pub fn options(&self) -> &WelchOptions {
        &self.opts
    }

    /// Bytes of heap held by the accumulator's own buffers (rings, segment, spectra, sums, window,
    /// FFT scratch): $O(C^2 L)$ and independent of how much has been pushed. The FFT plan's twiddle
    /// tables ($O(L)$, shared through the planner) are not counted.
    pub fn heap_bytes(&self) -> usize {
        use std::mem::size_of;
        (self.ring.capacity()
            + self.seg.capacity()
            + self.window.capacity()
            + self.overlap_corr_sq.capacity())
            * size_of::<f64>()
            + (self.scratch.capacity() + self.spec.capacity() + self.sums.capacity())
                * size_of::<c64>()
    }
}

/// Sum with four interleaved partial sums: independent add chains (about four times the
/// throughput of a serial sum) and a smaller rounding error; deterministic.
fn sum4(x: &[f64]) -> f64 {
    let mut acc = [0.0f64; 4];
    let mut quads = x.chunks_exact(4);
    for q in quads.by_ref() {
        acc[0] += q[0];
        acc[1] += q[1];
        acc[2] += q[2];
        acc[3] += q[3];
    }
    let tail: f64 = quads.remainder().iter().sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// Removes nothing, the mean, or the least-squares line from `x`, then multiplies by `w` (one pass
/// over the data after the sums).
fn detrend_and_window(x: &mut [f64], w: &[f64], detrend: SegmentDetrend) {
    let n = x.len();
    if n == 0 {
        return;
    }
    match detrend {
        SegmentDetrend::None => {
            x.iter_mut().zip(w).for_each(|(v, c)| *v *= c);
        }
        SegmentDetrend::Constant => {
            let mean = sum4(x) / n as f64;
            x.iter_mut().zip(w).for_each(|(v, c)| *v = (*v - mean) * c);
        }
        SegmentDetrend::Linear => {
            let nf = n as f64;
            let mean = sum4(x) / nf;
            let tc = (nf - 1.0) / 2.0;
            // Σ (t - t̄)² = n (n² - 1) / 12, zero only for n = 1
            let stt = nf * (nf * nf - 1.0) / 12.0;
            let slope = if stt > 0.0 {
                let mut acc = [0.0f64; 2];
                for (t, v) in x.iter().enumerate() {
                    acc[t & 1] += (t as f64 - tc) * (v - mean);
                }
                (acc[0] + acc[1]) / stt
            } else {
                0.0
            };
            x.iter_mut()
                .zip(w)
                .enumerate()
                .for_each(|(t, (v, c))| *v = (*v - mean - slope * (t as f64 - tc)) * c);
        }
    }
}

/// $\rho_l^2$ for $l = 1, 2, \dots$ while $l \cdot$ `step` $<$ `w.len()`: the squared normalised
/// overlap correlation of the window (FFT-based autocorrelation, $O(L \log L)$).
fn overlap_correlation_sq(w: &[f64], step: usize) -> Result<Vec<f64>> {
    let l = w.len();
    if step >= l {
        return Ok(Vec::new());
    }
    let r = crate::signal::analysis::autocorrelation_fft(w, l - 1, false)?;
    let r0 = r[0];
    Ok((1..)
        .map(|m| m * step)
        .take_while(|&lag| lag < l)
        .map(|lag| {
            let rho = r[lag] / r0;
            rho * rho
        })
        .collect())
}

/// Averaged one-sided auto and cross spectra of several channels, from [`WelchAccumulator`] or
/// [`welch_spectra`]. All frequencies in Hz.
#[derive(Debug, Clone, PartialEq)]
pub struct CrossSpectra {
    opts: WelchOptions,
    f_hz: Vec<f64>,
    n_channels: usize,
    n_samples: usize,
    n_segments: usize,
    effective_averages: f64,
    /// $S_{ij}$ at `data[(i * n_channels + j) * n_freq ..][.. n_freq]`.
    data: Vec<c64>,
}

impl CrossSpectra {
    /// The frequency grid $f_k = k f_s / L$ in Hz, $k = 0, \dots, \lfloor L/2 \rfloor$.
    pub fn f_hz(&self) -> &[f64] {
        &self.f_hz
    }

    /// Number of segments averaged, $K$.
    pub fn n_segments(&self) -> usize {
        self.n_segments
    }

    /// Number of channels.
    pub fn n_channels(&self) -> usize {
        self.n_channels
    }

    /// Samples per channel in the record (including any unused tail after the last segment).
    pub fn n_samples(&self) -> usize {
        self.n_samples
    }

    /// The options the spectra were computed with.
    pub fn options(&self) -> &WelchOptions {
        &self.opts
    }

    /// Welch's effective number of independent averages $n_{\text{eff}} \le K$, accounting for
    /// the correlation of overlapping windowed segments (see the [module documentation](self)).
    /// Equals $K$ without overlap.
    pub fn effective_averages(&self) -> f64 {
        self.effective_averages
    }

    fn check_channel(&self, name: &'static str, i: usize) -> Result<()> {
        if i < self.n_channels {
            Ok(())
        } else {
            Err(Error::invalid(
                name,
                format!(
                    "channel index {i} is out of range: the spectra have {} channels (0..{})",
                    self.n_channels, self.n_channels
                ),
            ))
        }
    }

    fn slice(&self, i: usize, j: usize) -> &[c64] {
        let nf = self.f_hz.len();
        let start = (i * self.n_channels + j) * nf;
        &self.data[start..start + nf]
    }

    /// The cross spectrum $S_{ij}(f_k)$: the scaled mean of $\overline{X_i} X_j$ (scipy's
    /// `csd(x_i, x_j)`); $S_{ii}$ is the auto spectrum (imaginary part exactly 0).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a channel index out of range.
    pub fn get(&self, i: usize, j: usize) -> Result<&[c64]> {
        self.check_channel("i", i)?;
        self.check_channel("j", j)?;
        Ok(self.slice(i, j))
    }

    /// The auto spectrum $S_{ii}(f_k)$ (scipy's `welch(x_i)`).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a channel index out of range.
    pub fn psd(&self, i: usize) -> Result<Vec<f64>> {
        self.check_channel("i", i)?;
        Ok(self.slice(i, i).iter().map(|z| z.re).collect())
    }

    /// Magnitude-squared coherence $\gamma^2_{ij} = |S_{ij}|^2 / (S_{ii} S_{jj})$ (scipy's
    /// `coherence(x_i, x_j)`).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a channel index out of range, or if a channel has exactly zero
    /// power at some line (coherence is undefined there; the message names the frequency).
    pub fn coherence(&self, i: usize, j: usize) -> Result<Vec<f64>> {
        self.check_channel("i", i)?;
        self.check_channel("j", j)?;
        let (sii, sjj, sij) = (self.slice(i, i), self.slice(j, j), self.slice(i, j));
        self.check_nonzero(i, i, "the coherence")?;
        self.check_nonzero(j, j, "the coherence")?;
        Ok(sij
            .iter()
            .zip(sii.iter().zip(sjj))
            .map(|(z, (a, b))| z.norm_sqr() / a.re / b.re)
            .collect())
    }

    /// Errors at the first line where $S_{ij}$ is exactly zero (`what` is the quantity that
    /// divides by it).
    fn check_nonzero(&self, i: usize, j: usize, what: &str) -> Result<()> {
        match self.slice(i, j).iter().position(|z| z.re == 0.0 && z.im == 0.0) {
            None => Ok(()),
            Some(k) => Err(Error::numerical(
                "Welch spectra",
                format!(
                    "the spectrum S[{i},{j}] is exactly zero at {} Hz (line {k}), so {what} is \
                     undefined there; excite that band, or check that channels {i} and {j} carry data",
                    self.f_hz[k]
                ),
            )),
        }
    }

    /// The $H_1$ estimate from input channel `i_in` to output channel `j_out`:
    /// $S_{ij} / S_{ii}$. Unbiased with output noise; biased by feedback (use a reference channel in
    /// closed loop, see the [module documentation](self)).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a channel index out of range; [`Error::Numerical`] if the
    /// input's auto spectrum is exactly zero at some line.
    pub fn h1(&self, i_in: usize, j_out: usize) -> Result<Vec<c64>> {
        self.check_channel("i_in", i_in)?;
        self.check_channel("j_out", j_out)?;
        let sii = self.slice(i_in, i_in);
        self.check_nonzero(i_in, i_in, "H1")?;
        Ok(self
            .slice(i_in, j_out)
            .iter()
            .zip(sii)
            .map(|(z, a)| z / a.re)
            .collect())
    }

    /// The $H_2$ estimate from input channel `i_in` to output channel `j_out`:
    /// $S_{jj} / S_{ji}$. Unbiased with input noise.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for a channel index out of range; [`Error::Numerical`] if the
    /// cross spectrum is exactly zero at some line.
    pub fn h2(&self, i_in: usize, j_out: usize) -> Result<Vec<c64>> {
        self.check_channel("i_in", i_in)?;
        self.check_channel("j_out", j_out)?;
        let sji = self.slice(j_out, i_in);
        self.check_nonzero(j_out, i_in, "H2")?;
        Ok(self
            .slice(j_out, j_out)
            .iter()
            .zip(sji)
            .map(|(b, z)| b.re / z)
            .collect())
    }

    /// The approximate variance $\mathrm E\,|\hat H_1 - H|^2 \approx
    /// (1-\gamma^2)\, S_{jj} / (n_{\text{eff}} S_{ii})$ of [`h1`](Self::h1) (Bendat and Piersol;
    /// first order, Gaussian data, $n_{\text{eff}}$ from
    /// [`effective_averages`](Self::effective_averages)). It is finite wherever $H_1$ is, also at
    /// zero coherence, and meaningless for a single segment (where $\hat\gamma^2 = 1$ and it is 0).
    ///
    /// # Errors
    /// As [`h1`](Self::h1).
    pub fn h1_variance(&self, i_in: usize, j_out: usize) -> Result<Vec<f64>> {
        self.check_channel("i_in", i_in)?;
        self.check_channel("j_out", j_out)?;
        let (sii, sjj, sij) = (
            self.slice(i_in, i_in),
            self.slice(j_out, j_out),
            self.slice(i_in, j_out),
        );
        self.check_nonzero(i_in, i_in, "H1")?;
        let n = self.effective_averages;
        Ok(sij
            .iter()
            .zip(sii.iter().zip(sjj))
            .map(|(z, (a, b))| {
                // (1 - γ²) S_jj = S_jj - |S_ij|² / S_ii
                let resid = (b.re - z.norm_sqr() / a.re).max(0.0);
                resid / (n * a.re)
            })
            .collect())
    }
}

/// Checks a one-shot input: options, equal lengths, finiteness, at least one segment.
fn check_record(names: &[&'static str], xs: &[&[f64]], opts: &WelchOptions) -> Result<()> {
    opts.validate()?;
    let n = xs.first().map_or(0, |x| x.len());
    for (name, x) in names.iter().zip(xs) {
        if x.len() != n {
            return Err(Error::DimensionMismatch {
                context: "Welch record lengths (every channel the same length)",
                expected: format!("{n} samples ({})", names[0]),
                got: format!("{} samples in {name}", x.len()),
            });
        }
        check_finite(name, x)?;
    }
    if opts.n_segments(n) == 0 {
        return Err(opts.too_short(n));
    }
    Ok(())
}

/// All auto and cross spectra of `channels` (equal-length records) in one pass; the records are
/// read in place through a [`WelchAccumulator`], never copied.
///
/// # Errors
/// [`Error::InvalidArgument`] for no channels, invalid options or a record shorter than `nperseg`;
/// [`Error::DimensionMismatch`] for records of different lengths; [`Error::NonFinite`] for a NaN or
/// infinite sample (what = `"channel c"`).
///
/// # Example
/// ```
/// use ambid_core::frf::welch::{welch_spectra, WelchOptions};
/// let a = vec![1.0, -1.0, 2.0, 0.5, 0.0, 1.0, -0.5, 0.25];
/// let b: Vec<f64> = a.iter().map(|v| -3.0 * v).collect();
/// let s = welch_spectra(&[&a, &b], &WelchOptions::new(8.0, 4)).unwrap();
/// assert_eq!((s.n_channels(), s.n_segments(), s.f_hz()), (2, 3, &[0.0, 2.0, 4.0][..]));
/// let h = s.h1(0, 1).unwrap();
/// assert!(h.iter().all(|z| (z.re + 3.0).abs() < 1e-12 && z.im.abs() < 1e-12));
/// assert!(welch_spectra(&[&a[..3]], &WelchOptions::new(8.0, 4)).is_err());
/// ```
pub fn welch_spectra<S: AsRef<[f64]>>(channels: &[S], opts: &WelchOptions) -> Result<CrossSpectra> {
    let mut acc = WelchAccumulator::new(channels.len(), opts)?;
    let n = channels.first().map_or(0, |x| x.as_ref().len());
    if let Some((c, x)) = channels
        .iter()
        .enumerate()
        .find(|(_, x)| x.as_ref().len() != n)
    {
        return Err(Error::DimensionMismatch {
            context: "welch_spectra (every channel the same length)",
            expected: format!("{n} samples (channel 0)"),
            got: format!("{} samples in channel {c}", x.as_ref().len()),
        });
    }
    if opts.n_segments(n) == 0 {
        return Err(opts.too_short(n));
    }
    acc.push(channels)?;
    acc.finish()
}

/// Power spectral density (or power spectrum) of `x` by Welch's method: `(f_hz, S_xx)`, as scipy's
/// `welch(x, fs, ...)`.
///
/// # Errors
/// [`Error::InvalidArgument`] for invalid options or a record shorter than `nperseg`;
/// [`Error::NonFinite`] for a NaN or infinite sample (what = `"x"`).
///
/// # Example
/// ```
/// use ambid_core::frf::welch::{psd, Scaling, WelchOptions};
/// use ambid_core::frf::window::Window;
/// // a 1 V amplitude cosine at 125 Hz (a line of a 256-point segment at 1 kHz): mean square 0.5 V²
/// let x: Vec<f64> = (0..4096).map(|k| (2.0 * std::f64::consts::PI * 125.0 * k as f64 / 1e3).cos()).collect();
/// let opts = WelchOptions { scaling: Scaling::Spectrum, window: Window::FlatTop, ..WelchOptions::new(1e3, 256) };
/// let (f, p) = psd(&x, &opts).unwrap();
/// assert_eq!(f[32], 125.0);
/// assert!((p[32] - 0.5).abs() < 1e-9);
/// ```
pub fn psd(x: &[f64], opts: &WelchOptions) -> Result<(Vec<f64>, Vec<f64>)> {
    check_record(&["x"], &[x], opts)?;
    let s = welch_spectra(&[x], opts)?;
    Ok((s.f_hz.clone(), s.psd(0)?))
}

/// Cross spectral density (or cross power spectrum) $S_{xy}$, the scaled mean of
/// $\overline{X} Y$: `(f_hz, S_xy)`, as scipy's `csd(x, y, fs, ...)`.
///
/// # Errors
/// As [`psd`], and [`Error::DimensionMismatch`] if `x` and `y` differ in length.
///
/// # Example
/// ```
/// use ambid_core::frf::welch::{csd, WelchOptions};
/// let x: Vec<f64> = (0..512).map(|k| ((k * k) % 17) as f64).collect();
/// let (_, sxx) = csd(&x, &x, &WelchOptions::new(1.0, 64)).unwrap();
/// assert!(sxx.iter().all(|z| z.im == 0.0 && z.re >= 0.0));
/// ```
pub fn csd(x: &[f64], y: &[f64], opts: &WelchOptions) -> Result<(Vec<f64>, Vec<c64>)> {
    check_record(&["x", "y"], &[x, y], opts)?;
    let s = welch_spectra(&[x, y], opts)?;
    Ok((s.f_hz.clone(), s.slice(0, 1).to_vec()))
}

/// Magnitude-squared coherence $|S_{xy}|^2 / (S_{xx} S_{yy})$: `(f_hz, γ²)`, as scipy's
/// `coherence(x, y, fs, ...)`.
///
/// # Errors
/// As [`csd`], and [`Error::Numerical`] if `x` or `y` has exactly zero power at some line.
///
/// # Example
/// ```
/// use ambid_core::frf::welch::{coherence, WelchOptions};
/// let x: Vec<f64> = (0..2048).map(|k| ((k * 7919) % 101) as f64 - 50.0).collect();
/// let y: Vec<f64> = x.iter().map(|v| 2.0 * v).collect();
/// let (_, c) = coherence(&x, &y, &WelchOptions::new(1.0, 128)).unwrap();
/// assert!(c.iter().all(|g| (g - 1.0).abs() < 1e-9));
/// ```
pub fn coherence(x: &[f64], y: &[f64], opts: &WelchOptions) -> Result<(Vec<f64>, Vec<f64>)> {
    check_record(&["x", "y"], &[x, y], opts)?;
    let s = welch_spectra(&[x, y], opts)?;
    Ok((s.f_hz.clone(), s.coherence(0, 1)?))
}

/// Empirical transfer-function estimate from one record: $\hat G(f_k) = Y(k) / U(k)$ with
/// $U, Y$ the DFTs of the whole (optionally windowed) records, $f_k = k f_s / N$,
/// $k = 0, \dots, \lfloor N/2 \rfloor$. Returns `(f_hz, G)`.
///
/// No detrending and no averaging: the estimate is exact for periodic data analysed over whole
/// periods with the rectangular window (`window = None`), and noisy (variance not decreasing with
/// $N$) for random data, which wants [`welch_spectra`] and [`CrossSpectra::h1`]. A window
/// (periodic, applied to both records) reduces leakage; its scaling cancels in the ratio.
///
/// **Lines where $U(k)$ is exactly zero are skipped**: they are absent from both returned vectors
/// (compare `f_hz` with the full grid to find them). Lines where $U$ is merely small are kept; select
/// the excited lines yourself for multisine or PRBS data.
///
/// # Errors
/// [`Error::InvalidArgument`] for `fs` not finite and $> 0$ or fewer than 2 samples;
/// [`Error::DimensionMismatch`] for records of different lengths; [`Error::NonFinite`] for NaN or
/// infinite samples (what = `"u"` or `"y"`).
///
/// # Example
/// ```
/// use ambid_core::frf::welch::etfe;
/// // one period of a periodic input through y[n] = 2 u[n-1] (circularly): G = 2 e^{-j2πf/fs}
/// let u = [1.0, 0.0, 3.0, -1.0, 2.0, 0.5, 0.0, 1.0];
/// let y: Vec<f64> = (0..8).map(|n| 2.0 * u[(n + 7) % 8]).collect();
/// let (f, g) = etfe(&u, &y, 8.0, None).unwrap();
/// for (fk, gk) in f.iter().zip(&g) {
///     let want = num_complex::Complex::from_polar(2.0, -2.0 * std::f64::consts::PI * fk / 8.0);
///     assert!((gk - want).norm() < 1e-12);
/// }
/// ```
pub fn etfe(u: &[f64], y: &[f64], fs: f64, window: Option<Window>) -> Result<(Vec<f64>, Vec<c64>)> {
    if !(fs.is_finite() && fs > 0.0) {
        return Err(Error::invalid(
            "fs",
            format!("the sampling frequency must be a finite number of Hz > 0, got {fs}"),
        ));
    }
    if u.len() != y.len() {
        return Err(Error::DimensionMismatch {
            context: "etfe (u and y the same length)",
            expected: format!("{} samples (u)", u.len()),
            got: format!("{} samples in y", y.len()),
        });
    }
    let n = u.len();
    if n < 2 {
        return Err(Error::invalid(
            "u",
            format!("the records have {n} samples; pass at least 2"),
        ));
    }
    check_finite("u", u)?;
    check_finite("y", y)?;
    let w = match window {
        Some(w) => w.coefficients(n, true)?,
        None => vec![1.0; n],
    };
    let fft = RealFftPlanner::<f64>::new().plan_fft_forward(n);
    let mut scratch = fft.make_scratch_vec();
    let mut buf: Vec<f64> = u.iter().zip(&w).map(|(a, b)| a * b).collect();
    let mut uf = fft.make_output_vec();
    fft.process_with_scratch(&mut buf, &mut uf, &mut scratch)
        .map_err(|e| Error::numerical("etfe FFT", e.to_string()))?;
    buf.iter_mut()
        .zip(y.iter().zip(&w))
        .for_each(|(b, (a, c))| *b = a * c);
    let mut yf = fft.make_output_vec();
    fft.process_with_scratch(&mut buf, &mut yf, &mut scratch)
        .map_err(|e| Error::numerical("etfe FFT", e.to_string()))?;
    let nf = n as f64;
    let (f, g) = uf
        .iter()
        .zip(&yf)
        .enumerate()
        .filter(|(_, (a, _))| !(a.re == 0.0 && a.im == 0.0))
        .map(|(k, (a, b))| (k as f64 * fs / nf, b / a))
        .unzip();
    Ok((f, g))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(n: usize, seed: u64) -> Vec<f64> {
        // small deterministic LCG, enough for unit tests
        let mut s = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (0..n)
            .map(|_| {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
            })
            .collect()
    }

    #[test]
    fn detrend_removes_lines_and_means() {
        let ones = vec![1.0; 37];
        let mut x: Vec<f64> = (0..37).map(|t| 3.0 - 0.25 * t as f64).collect();
        detrend_and_window(&mut x, &ones, SegmentDetrend::Linear);
        assert!(x.iter().all(|v| v.abs() < 1e-13), "{x:?}");
        let mut x = vec![2.5; 5];
        detrend_and_window(&mut x, &ones, SegmentDetrend::Constant);
        assert!(x.iter().all(|v| *v == 0.0));
        let mut x = vec![7.0];
        detrend_and_window(&mut x, &ones, SegmentDetrend::Linear);
        assert_eq!(x, vec![0.0]);
        let mut x = vec![1.0, 2.0, 3.0];
        detrend_and_window(&mut x, &[0.5, 1.0, 2.0], SegmentDetrend::None);
        assert_eq!(x, vec![0.5, 2.0, 6.0]);
        assert_eq!(sum4(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]), 28.0);
    }

    #[test]
    fn hann_half_overlap_correlation_is_one_sixth() {
        let w = Window::Hann.coefficients(512, true).unwrap();
        let r = overlap_correlation_sq(&w, 256).unwrap();
        assert_eq!(r.len(), 1);
        assert!((r[0] - 1.0 / 36.0).abs() < 1e-14, "{}", r[0]);
        // K = 2: n_eff = 2 / (1 + 2 · ½ · 1/36) = 72/37
        let x = signal(768, 1);
        let s = welch_spectra(&[&x], &WelchOptions::new(1.0, 512)).unwrap();
        assert_eq!(s.n_segments(), 2);
        assert!((s.effective_averages() - 72.0 / 37.0).abs() < 1e-13);
        // no overlap: n_eff = K
        let o = WelchOptions {
            noverlap: 0,
            ..WelchOptions::new(1.0, 128)
        };
        let s = welch_spectra(&[&x], &o).unwrap();
        assert_eq!(s.effective_averages(), 6.0);
    }

    #[test]
    fn heap_is_bounded() {
        let opts = WelchOptions::new(1.0, 64);
        let mut acc = WelchAccumulator::new(3, &opts).unwrap();
        let before = acc.heap_bytes();
        let x = signal(10_000, 2);
        for _ in 0..5 {
            acc.push(&[&x, &x, &x]).unwrap();
        }
        assert_eq!(acc.heap_bytes(), before);
        assert_eq!(acc.n_samples(), 50_000);
        assert_eq!(acc.n_segments(), opts.n_segments(50_000));
    }

    #[test]
    fn parseval_for_white_noise_density() {
        // Σ S Δf equals the mean power of the detrended, windowed segments up to the window
        // normalisation: with the rectangular window and no detrend it is exactly the mean square.
        let x = signal(4096, 3);
        let o = WelchOptions {
            window: Window::Rectangular,
            detrend: SegmentDetrend::None,
            noverlap: 0,
            ..WelchOptions::new(50.0, 256)
        };
        let (f, p) = psd(&x, &o).unwrap();
        let df = f[1] - f[0];
        let total: f64 = p.iter().sum::<f64>() * df;
        let ms = x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64;
        assert!((total - ms).abs() < 1e-12 * ms, "{total} vs {ms}");
    }
}
