//! The host denoiser's input gradient for one block of samples: the vector–Jacobian product of
//! the forward pass that `host.rs` recorded, back through the heads and the graph layers to V
//! and E.
//!
//! Why it exists: it is half the inference path's code and mirrors `forward_block` step by step
//! in reverse; apart, each of the two reads as one pass.

use super::*;

impl HostDenoiser {
    pub(super) fn backward_block(
        &self,
        d_eps_v: &[f32],
        d_eps_e: &[f32],
        d_v: &mut [f32],
        d_e: &mut [f32],
        blk: &mut Block,
    ) {
        let n = blk.n;
        let w = self.w;
        let (rv, re, ru) = (K * n, D * n, NUM_EDGES * n);
        let nl = self.layers.len();
        d_v.fill(0.0);
        d_e.fill(0.0);
        // Heads.
        sized(&mut blk.dhw, rv * w);
        sized(&mut blk.dgw, ru * w);
        for (k, (&(o, _), head)) in NODE_SLICES.iter().zip(&self.node_heads).enumerate() {
            let d_out = View::cols(d_eps_v, NODE_DIM, o);
            head.backward(
                d_out,
                &blk.head_acts[k],
                &mut blk.dhw,
                &mut d_v[o..],
                NODE_DIM,
                rv,
                w,
                &mut blk.dacts,
            );
        }
        let base = self.node_heads.len();
        for (k, (&(o, _), head)) in EDGE_SLICES.iter().zip(&self.edge_heads).enumerate() {
            let d_out = View::cols(d_eps_e, EDGE_DIM, o);
            head.backward(
                d_out,
                &blk.head_acts[base + k],
                &mut blk.dgw,
                &mut d_e[o..],
                EDGE_DIM,
                ru,
                w,
                &mut blk.dacts,
            );
        }
        // Wide skips.
        blk.dhs.resize_with(nl + 1, Vec::new);
        blk.dgs.resize_with(nl + 1, Vec::new);
        for l in 0..=nl {
            sized(&mut blk.dhs[l], rv * w);
            mm(
                &mut blk.dhs[l],
                w,
                View::rows(&blk.dhw, w),
                View::transposed(self.node_wide.rows(l * w, w), w),
                rv,
                w,
                w,
                false,
            );
            sized(&mut blk.dgs[l], ru * w);
            mm(
                &mut blk.dgs[l],
                w,
                View::rows(&blk.dgw, w),
                View::transposed(self.edge_wide.rows(l * w, w), w),
                ru,
                w,
                w,
                false,
            );
        }
        blk.dh.clear();
        blk.dh.extend_from_slice(&blk.dhs[nl]);
        sized(&mut blk.dg, re * w);
        scatter_upper(&mut blk.dg, &blk.dgs[nl], n, w);

        let (h, hc) = (self.heads, w / self.heads);
        for (l, layer) in self.layers.iter().enumerate().rev() {
            let tape = &blk.tapes[l];
            // 7–8. dP₂ = dh ⊙ SiLU′; into v₁ and the pooled maximum.
            let no = &layer.node_out;
            blk.t1.clear();
            blk.t1.extend_from_slice(&blk.dh);
            mul_into(&mut blk.t1, &tape.d_out);
            sized(&mut blk.dv1, rv * w);
            mm(
                &mut blk.dv1,
                w,
                View::rows(&blk.t1, w),
                View::transposed(no.rows(0, w), w),
                rv,
                w,
                w,
                false,
            );
            sized(&mut blk.dpool, n * w);
            for s in 0..n {
                for i in 0..K {
                    add_into(
                        &mut blk.dpool[s * w..(s + 1) * w],
                        &blk.t1[(s * K + i) * w..][..w],
                    );
                }
            }
            sized(&mut blk.dgmax, n * w);
            mm(
                &mut blk.dgmax,
                w,
                View::rows(&blk.dpool, w),
                View::transposed(no.rows(w, w), w),
                n,
                w,
                w,
                false,
            );
            for s in 0..n {
                for c in 0..w {
                    let i = tape.argmax[s * w + c] as usize;
                    blk.dv1[(s * K + i) * w + c] += blk.dgmax[s * w + c];
                }
            }
            // 6. Self term.
            blk.t1.clear();
            blk.t1.extend_from_slice(&blk.dv1);
            mul_into(&mut blk.t1, &tape.d_self);
            sized(&mut blk.dvb, rv * w);
            mm(
                &mut blk.dvb,
                w,
                View::rows(&blk.t1, w),
                View::transposed(&layer.self_term.w, w),
                rv,
                w,
                w,
                false,
            );
            // 3–5. Attention: into u, α → logits → q, k.
            blk.du.clear();
            blk.du.extend_from_slice(&blk.dg);
            sized(&mut blk.dalpha, n * h * D);
            sized(&mut blk.dq, rv * w);
            sized(&mut blk.dk, rv * w);
            for s in 0..n {
                for hh in 0..h {
                    for i in 0..K {
                        let dm = &blk.dv1[(s * K + i) * w + hh * hc..][..hc];
                        let at = ((s * h + hh) * K + i) * K;
                        let al = &tape.alpha[at..at + K];
                        let da = &mut blk.dalpha[at..at + K];
                        for j in 0..K {
                            let row = (s * D + i * K + j) * w + hh * hc;
                            let uij = &tape.u[row..row + hc];
                            da[j] = dm.iter().zip(uij).map(|(x, y)| x * y).sum();
                            blk.du[row..row + hc]
                                .iter_mut()
                                .zip(dm)
                                .for_each(|(d, m)| *d += al[j] * m);
                        }
                        let dot: f32 = al.iter().zip(da.iter()).map(|(a, d)| a * d).sum();
                        for (d, a) in da.iter_mut().zip(al) {
                            *d = a * (*d - dot) * self.scale;
                        }
                        for (j, &c) in da.iter().enumerate() {
                            let kj = &tape.k[(s * K + j) * w + hh * hc..][..hc];
                            let qi = &tape.q[(s * K + i) * w + hh * hc..][..hc];
                            blk.dq[(s * K + i) * w + hh * hc..][..hc]
                                .iter_mut()
                                .zip(kj)
                                .for_each(|(d, k)| *d += c * k);
                            blk.dk[(s * K + j) * w + hh * hc..][..hc]
                                .iter_mut()
                                .zip(qi)
                                .for_each(|(d, q)| *d += c * q);
                        }
                    }
                }
            }
            mm(
                &mut blk.dvb,
                w,
                View::rows(&blk.dq, w),
                View::transposed(&layer.query.w, w),
                rv,
                w,
                w,
                true,
            );
            mm(
                &mut blk.dvb,
                w,
                View::rows(&blk.dk, w),
                View::transposed(&layer.key.w, w),
                rv,
                w,
                w,
                true,
            );
            // 2. Edge messages.
            let m1 = &layer.edge_mlp1;
            sized(&mut blk.hid, re * w);
            mm(
                &mut blk.hid,
                w,
                View::rows(&blk.du, w),
                View::transposed(&layer.edge_mlp2.w, w),
                re,
                w,
                w,
                false,
            );
            mul_into(&mut blk.hid, &tape.d_hid);
            sized(&mut blk.da, rv * w);
            sized(&mut blk.db, rv * w);
            for s in 0..n {
                for i in 0..K {
                    for j in 0..K {
                        let row = &blk.hid[(s * D + i * K + j) * w..][..w];
                        add_into(&mut blk.da[(s * K + i) * w..][..w], row);
                        add_into(&mut blk.db[(s * K + j) * w..][..w], row);
                    }
                }
            }
            mm(
                &mut blk.dvb,
                w,
                View::rows(&blk.da, w),
                View::transposed(m1.rows(0, w), w),
                rv,
                w,
                w,
                true,
            );
            mm(
                &mut blk.dvb,
                w,
                View::rows(&blk.db, w),
                View::transposed(m1.rows(w, w), w),
                rv,
                w,
                w,
                true,
            );
            sized(&mut blk.eb, re * w);
            mm(
                &mut blk.eb,
                w,
                View::rows(&blk.hid, w),
                View::transposed(m1.rows(2 * w, w), w),
                re,
                w,
                w,
                false,
            );
            mul_into(&mut blk.eb, &tape.d_eb);
            // 1. Bindings → the layer's inputs, plus the wide skip of the layer below.
            mm(
                &mut blk.dg,
                w,
                View::rows(&blk.eb, w),
                View::transposed(layer.edge_bind.rows(0, w), w),
                re,
                w,
                w,
                false,
            );
            scatter_upper(&mut blk.dg, &blk.dgs[l], n, w);
            mul_into(&mut blk.dvb, &tape.d_vb);
            mm(
                &mut blk.dh,
                w,
                View::rows(&blk.dvb, w),
                View::transposed(layer.node_bind.rows(0, w), w),
                rv,
                w,
                w,
                false,
            );
            add_into(&mut blk.dh, &blk.dhs[l]);
        }
        // Embeddings.
        mm(
            d_v,
            NODE_DIM,
            View::rows(&blk.dh, w),
            View::transposed(&self.node_w, w),
            rv,
            w,
            NODE_DIM,
            true,
        );
        sized(&mut blk.ddense, re * EDGE_DIM);
        mm(
            &mut blk.ddense,
            EDGE_DIM,
            View::rows(&blk.dg, w),
            View::transposed(&self.edge_w, w),
            re,
            w,
            EDGE_DIM,
            false,
        );
        for s in 0..n {
            for i in 0..K {
                for j in 0..K {
                    if let Some((p, swapped)) = dense_source(i, j) {
                        let src = &blk.ddense[(s * D + i * K + j) * EDGE_DIM..][..EDGE_DIM];
                        let dst = &mut d_e[(s * NUM_EDGES + p) * EDGE_DIM..][..EDGE_DIM];
                        for (c, g) in src.iter().enumerate() {
                            dst[if swapped { swap(c) } else { c }] += g;
                        }
                    }
                }
            }
        }
    }
}
