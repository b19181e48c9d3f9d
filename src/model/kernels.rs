//! The dense kernels of the host inference paths ([`super::host_decoder`] and
//! [`super::denoiser::host`]): a linear layer's weights in a plain `f32` buffer, GEMM on
//! strided row-major views, and the vectorised activations.
//!
//! Why it exists: burn's Flex backend evaluates every op of a small network as a separate tensor
//! op (an allocation, a pass over memory, and SiLU as scalar `expf`), which is most of the
//! denoiser's time at the batch sizes sampling uses. The host paths call these kernels on
//! buffers they own, so bias and residual additions fold into the GEMM's accumulation, nothing
//! is allocated per call, and the activations run in SIMD registers.
//!
//! Determinism: the GEMM is the `gemm` crate's single-threaded kernel (callers parallelise over
//! fixed blocks of rows, never over the reduction), and the activations use plain multiplies
//! and adds (no fused multiply-add), so the AVX2 and the baseline SSE2 builds of a kernel give
//! the same bits.

use burn::nn::Linear;

/// A linear layer: `w` [d_in, d_out] row-major (burn's layout), `b` [d_out] or none.
#[derive(Debug, Clone)]
pub(crate) struct HostLinear {
    pub w: Vec<f32>,
    pub b: Option<Vec<f32>>,
    pub d_in: usize,
    pub d_out: usize,
}

impl HostLinear {
    /// Copy `l`'s weights.
    pub fn new(l: &Linear) -> Self {
        let [d_in, d_out] = l.weight.shape().dims::<2>();
        let w = l
            .weight
            .val()
            .into_data()
            .try_to_vec::<f32>()
            .expect("weights are f32");
        let b = l.bias.as_ref().map(|b| {
            b.val()
                .into_data()
                .try_to_vec::<f32>()
                .expect("biases are f32")
        });
        HostLinear { w, b, d_in, d_out }
    }

    /// The weight rows `start..start + len` as a contiguous `[len, d_out]` matrix.
    pub fn rows(&self, start: usize, len: usize) -> &[f32] {
        &self.w[start * self.d_out..(start + len) * self.d_out]
    }

    /// `dst` [rows, d_out] = (accumulate ? dst : 0) + bias + `x` [rows, d_in] · W.
    pub fn apply(&self, x: &[f32], dst: &mut [f32], rows: usize, accumulate: bool) {
        if !accumulate {
            dst[..rows * self.d_out].fill(0.0);
        }
        if let Some(b) = &self.b {
            add_rows(&mut dst[..rows * self.d_out], b);
        }
        matmul_acc(dst, x, &self.w, rows, self.d_in, self.d_out);
    }
}

/// A read-only matrix view: element (r, c) is `data[r · rs + c · cs]`.
#[derive(Clone, Copy)]
pub(crate) struct View<'a> {
    pub data: &'a [f32],
    pub rs: usize,
    pub cs: usize,
}

impl<'a> View<'a> {
    /// A contiguous row-major matrix with `cols` columns.
    pub fn rows(data: &'a [f32], cols: usize) -> Self {
        View {
            data,
            rs: cols,
            cs: 1,
        }
    }

    /// Columns `start..` of a row-major matrix with row stride `rs`.
    pub fn cols(data: &'a [f32], rs: usize, start: usize) -> Self {
        View {
            data: &data[start..],
            rs,
            cs: 1,
        }
    }

    /// The transpose of a contiguous row-major `[rows, cols]` matrix, as `[cols, rows]`.
    pub fn transposed(data: &'a [f32], cols: usize) -> Self {
        View {
            data,
            rs: 1,
            cs: cols,
        }
    }

    fn fits(&self, rows: usize, cols: usize) -> bool {
        rows == 0 || cols == 0 || (rows - 1) * self.rs + (cols - 1) * self.cs < self.data.len()
    }
}

/// `dst` [m, n] (row stride `dst_rs`) = (accumulate ? dst : 0) + `a` [m, k] · `b` [k, n].
#[allow(clippy::too_many_arguments)]
pub(crate) fn mm(
    dst: &mut [f32],
    dst_rs: usize,
    a: View<'_>,
    b: View<'_>,
    m: usize,
    k: usize,
    n: usize,
    accumulate: bool,
) {
    if m == 0 || n == 0 {
        return;
    }
    assert!(
        (m - 1) * dst_rs + n <= dst.len() && n <= dst_rs && a.fits(m, k) && b.fits(k, n),
        "mm: views out of bounds"
    );
    if k == 0 {
        if !accumulate {
            for r in 0..m {
                dst[r * dst_rs..r * dst_rs + n].fill(0.0);
            }
        }
        return;
    }
    // SAFETY: every element the kernel touches lies inside its buffer (asserted above: the last
    // row and column of each view are in bounds and the strides are non-negative), and `dst` is
    // a unique borrow that cannot alias the shared `a` and `b`.
    unsafe {
        gemm::gemm(
            m,
            n,
            k,
            dst.as_mut_ptr(),
            1,
            dst_rs as isize,
            accumulate,
            a.data.as_ptr(),
            a.cs as isize,
            a.rs as isize,
            b.data.as_ptr(),
            b.cs as isize,
            b.rs as isize,
            1.0f32,
            1.0f32,
            false,
            false,
            false,
            gemm::Parallelism::None,
        );
    }
}

/// `dst` [m, n] += `a` [m, k] · `b` [k, n], all row-major and contiguous.
pub(crate) fn matmul_acc(dst: &mut [f32], a: &[f32], b: &[f32], m: usize, k: usize, n: usize) {
    mm(dst, n, View::rows(a, k), View::rows(b, n), m, k, n, true);
}

/// `dst` [m, n] += `a` [m, k] · `b`ᵀ for `b` [n, k], all row-major and contiguous.
pub(crate) fn matmul_bt_acc(dst: &mut [f32], a: &[f32], b: &[f32], m: usize, k: usize, n: usize) {
    mm(
        dst,
        n,
        View::rows(a, k),
        View::transposed(b, k),
        m,
        k,
        n,
        true,
    );
}

/// `dst` [m, n] += `a`ᵀ · `b` for `a` [k, m] and `b` [k, n], all row-major and contiguous (a
/// weight gradient: layer inputs [rows, d_in]ᵀ · output gradients [rows, d_out]).
pub(crate) fn matmul_at_acc(dst: &mut [f32], a: &[f32], b: &[f32], m: usize, k: usize, n: usize) {
    mm(
        dst,
        n,
        View::transposed(a, m),
        View::rows(b, n),
        m,
        k,
        n,
        true,
    );
}

/// Add `row` to every row of `dst` (a bias).
pub(crate) fn add_rows(dst: &mut [f32], row: &[f32]) {
    for r in dst.chunks_exact_mut(row.len()) {
        add_into(r, row);
    }
}

/// `dst` += `src`, elementwise.
pub(crate) fn add_into(dst: &mut [f32], src: &[f32]) {
    dst.iter_mut().zip(src).for_each(|(d, s)| *d += s);
}

/// e^x for x in [−87, 88] (clamped outside), within 2 ulp: Cephes' `expf` (range reduction
/// by ln 2 in two parts, a degree-5 minimax polynomial, the exponent written into the bits),
/// with the rounding done by the 1.5 · 2²³ trick so that the loop vectorises on SSE2.
#[inline(always)]
fn exp_approx(x: f32) -> f32 {
    const ROUND: f32 = 12_582_912.0; // 1.5 · 2²³
    let x = x.clamp(-87.0, 88.0);
    let n = (x * std::f32::consts::LOG2_E + ROUND) - ROUND;
    let r = x - n * 0.693_359_4 - n * -2.121_944_4e-4;
    let mut p = 1.987_569_1e-4f32;
    p = p * r + 1.398_199_9e-3;
    p = p * r + 8.333_452e-3;
    p = p * r + 4.166_579_6e-2;
    p = p * r + 1.666_666_5e-1;
    p = p * r + 0.5;
    let y = p * r * r + r + 1.0;
    y * f32::from_bits(((n as i32 + 127) as u32) << 23)
}

#[inline(always)]
fn silu_body(x: &mut [f32]) {
    for x in x.iter_mut() {
        *x *= 1.0 / (1.0 + exp_approx(-*x));
    }
}

#[inline(always)]
fn silu_deriv_body(x: &mut [f32], deriv: &mut [f32]) {
    for (x, d) in x.iter_mut().zip(deriv.iter_mut()) {
        let s = 1.0 / (1.0 + exp_approx(-*x));
        *d = s * (1.0 + *x * (1.0 - s));
        *x *= s;
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn silu_avx2(x: &mut [f32]) {
    silu_body(x)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn silu_deriv_avx2(x: &mut [f32], deriv: &mut [f32]) {
    silu_deriv_body(x, deriv)
}

/// x ← SiLU(x) = x σ(x), in place.
pub(crate) fn silu(x: &mut [f32]) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { silu_avx2(x) };
    }
    silu_body(x)
}

/// x ← SiLU(x) in place, and `deriv` ← SiLU′(x) = σ(x) (1 + x (1 − σ(x))) of the input.
pub(crate) fn silu_with_deriv(x: &mut [f32], deriv: &mut [f32]) {
    assert_eq!(x.len(), deriv.len(), "silu: buffer lengths");
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { silu_deriv_avx2(x, deriv) };
    }
    silu_deriv_body(x, deriv)
}

/// `g` ← `g` ⊙ `d` (a backward pass through an activation whose derivative is `d`).
pub(crate) fn mul_into(g: &mut [f32], d: &[f32]) {
    g.iter_mut().zip(d).for_each(|(g, d)| *g *= d);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_is_within_two_ulp_of_libm() {
        let mut worst = 0.0f64;
        let mut x = -87.0f32;
        while x <= 88.0 {
            let (got, want) = (exp_approx(x) as f64, (x as f64).exp());
            worst = worst.max(((got - want) / want).abs());
            x += 0.0137;
        }
        assert!(worst < 2.5e-7, "relative error {worst}");
    }

    #[test]
    fn silu_and_its_derivative_match_the_formula() {
        let xs: Vec<f32> = (-400..400)
            .map(|i| i as f32 * 0.05)
            .chain([-120.0, 120.0])
            .collect();
        let mut y = xs.clone();
        let mut d = vec![0.0; xs.len()];
        silu_with_deriv(&mut y, &mut d);
        let mut y2 = xs.clone();
        silu(&mut y2);
        let differ = y
            .iter()
            .zip(&y2)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(differ, 0, "the two SiLU kernels agree bit for bit");
        for ((&x, &y), &d) in xs.iter().zip(&y).zip(&d) {
            let s = 1.0 / (1.0 + (-(x as f64)).exp());
            let (wy, wd) = (x as f64 * s, s * (1.0 + x as f64 * (1.0 - s)));
            assert!(
                (y as f64 - wy).abs() <= 1e-6 * (1.0 + wy.abs()),
                "silu({x}) = {y}, want {wy}"
            );
            assert!((d as f64 - wd).abs() <= 1e-6, "silu'({x}) = {d}, want {wd}");
        }
        // Far tails: SiLU(−120) is 0 to f32 precision, SiLU(120) is 120.
        assert!(y[y.len() - 2].abs() < 1e-30 && y[y.len() - 1] == 120.0);
    }

    #[test]
    fn strided_gemm_reads_column_blocks_and_transposes() {
        // a [2, 3] inside a row stride of 5 at column 1; b = transpose of c [2, 3].
        let a = [0.0, 1.0, 2.0, 3.0, 0.0, 0.0, 4.0, 5.0, 6.0, 0.0];
        let c = [1.0, 0.0, 2.0, 0.0, 1.0, 0.0];
        let mut dst = [10.0f32; 4];
        mm(
            &mut dst,
            2,
            View::cols(&a, 5, 1),
            View::transposed(&c, 3),
            2,
            3,
            2,
            true,
        );
        assert_eq!(
            dst,
            [10.0 + 1.0 + 6.0, 10.0 + 2.0, 10.0 + 4.0 + 12.0, 10.0 + 5.0]
        );
        mm(
            &mut dst,
            2,
            View::cols(&a, 5, 1),
            View::transposed(&c, 3),
            2,
            3,
            2,
            false,
        );
        assert_eq!(dst, [7.0, 2.0, 16.0, 5.0]);
    }
}
