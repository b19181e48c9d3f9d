//! One NAP output head of the host denoiser: a hidden Linear → LeakyReLU stack whose output
//! layer reads `[input ; every activation]`, forward and input gradient.
//!
//! Why it exists: the eight heads (node and edge, one per feature slice) are the same small
//! network; keeping it apart leaves `host.rs` with the graph layers and the batching.

use super::*;

/// One NAP head (hidden Linear → LeakyReLU, output over `[input ; every activation]`).
#[derive(Debug, Clone)]
pub(super) struct Head {
    pub(super) hidden: Vec<HostLinear>,
    pub(super) out: HostLinear,
    /// Width of the slice of V or E the head reads besides the features.
    pub(super) slice: usize,
}

impl Head {
    pub(super) fn new(h: &crate::model::denoiser::WideMlp, slice: usize) -> Self {
        Head {
            hidden: h.hidden.iter().map(HostLinear::new).collect(),
            out: HostLinear::new(&h.out),
            slice,
        }
    }

    /// out [m, slice] (row stride `out_rs`) = head([feat ; x]) with `feat` [m, w] and `x` a
    /// column view of V or E; `acts` receives the hidden activations.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn forward(
        &self,
        feat: &[f32],
        x: View<'_>,
        out: &mut [f32],
        out_rs: usize,
        m: usize,
        w: usize,
        acts: &mut Vec<Vec<f32>>,
    ) {
        acts.resize_with(self.hidden.len(), Vec::new);
        let ns = self.slice;
        for (k, l) in self.hidden.iter().enumerate() {
            let (done, rest) = acts.split_at_mut(k);
            let act = &mut rest[0];
            sized(act, m * l.d_out);
            add_rows(act, l.b.as_deref().expect("head layers have biases"));
            if k == 0 {
                mm(
                    act,
                    l.d_out,
                    View::rows(feat, w),
                    View::rows(l.rows(0, w), l.d_out),
                    m,
                    w,
                    l.d_out,
                    true,
                );
                mm(
                    act,
                    l.d_out,
                    x,
                    View::rows(l.rows(w, ns), l.d_out),
                    m,
                    ns,
                    l.d_out,
                    true,
                );
            } else {
                let prev = &done[k - 1];
                mm(
                    act,
                    l.d_out,
                    View::rows(prev, l.d_in),
                    View::rows(&l.w, l.d_out),
                    m,
                    l.d_in,
                    l.d_out,
                    true,
                );
            }
            leaky(act);
        }
        let o = &self.out;
        let b = o.b.as_deref().expect("head outputs have biases");
        for r in 0..m {
            out[r * out_rs..r * out_rs + ns].copy_from_slice(b);
        }
        mm(
            out,
            out_rs,
            View::rows(feat, w),
            View::rows(o.rows(0, w), ns),
            m,
            w,
            ns,
            true,
        );
        mm(
            out,
            out_rs,
            x,
            View::rows(o.rows(w, ns), ns),
            m,
            ns,
            ns,
            true,
        );
        let mut off = w + ns;
        for (act, l) in acts.iter().zip(&self.hidden) {
            mm(
                out,
                out_rs,
                View::rows(act, l.d_out),
                View::rows(o.rows(off, l.d_out), ns),
                m,
                l.d_out,
                ns,
                true,
            );
            off += l.d_out;
        }
    }

    /// d_feat [m, w] += ∂/∂feat and d_x (columns of a matrix with row stride `dx_rs`) +=
    /// ∂/∂x of Σ ⟨d_out, head⟩, with `acts` from the forward pass.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn backward(
        &self,
        d_out: View<'_>,
        acts: &[Vec<f32>],
        d_feat: &mut [f32],
        d_x: &mut [f32],
        dx_rs: usize,
        m: usize,
        w: usize,
        dacts: &mut Vec<Vec<f32>>,
    ) {
        let ns = self.slice;
        let o = &self.out;
        let hid = self.hidden.len();
        dacts.resize_with(hid, Vec::new);
        let mut off: Vec<usize> = Vec::with_capacity(hid);
        let mut at = w + ns;
        for l in &self.hidden {
            off.push(at);
            at += l.d_out;
        }
        for k in (0..hid).rev() {
            let l = &self.hidden[k];
            let (lo, hi) = dacts.split_at_mut(k + 1);
            let da = &mut lo[k];
            sized(da, m * l.d_out);
            mm(
                da,
                l.d_out,
                d_out,
                View::transposed(o.rows(off[k], l.d_out), ns),
                m,
                ns,
                l.d_out,
                false,
            );
            if k + 1 < hid {
                let next = &self.hidden[k + 1];
                mm(
                    da,
                    l.d_out,
                    View::rows(&hi[0], next.d_out),
                    View::transposed(&next.w, next.d_out),
                    m,
                    next.d_out,
                    l.d_out,
                    true,
                );
            }
            leaky_backward(da, &acts[k]);
        }
        mm(
            d_feat,
            w,
            d_out,
            View::transposed(o.rows(0, w), ns),
            m,
            ns,
            w,
            true,
        );
        mm(
            d_x,
            dx_rs,
            d_out,
            View::transposed(o.rows(w, ns), ns),
            m,
            ns,
            ns,
            true,
        );
        if let Some(l0) = self.hidden.first() {
            let d0 = View::rows(&dacts[0], l0.d_out);
            mm(
                d_feat,
                w,
                d0,
                View::transposed(l0.rows(0, w), l0.d_out),
                m,
                l0.d_out,
                w,
                true,
            );
            mm(
                d_x,
                dx_rs,
                d0,
                View::transposed(l0.rows(w, ns), l0.d_out),
                m,
                l0.d_out,
                ns,
                true,
            );
        }
    }
}
