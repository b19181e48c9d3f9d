//! Evaluation: PhysNAP's guidance metrics ([`guided`]).
//!
//! Why it exists: the paper's Table 1 compares guidance variants by how well samples fit the
//! observed cloud (E_pc, D_pc) and how physically plausible they are (E_pen, E_mob). These are
//! pure functions of a generated sample; the generative metrics (MMD, COV, 1-NNA) live beside
//! them.

pub mod guided;
