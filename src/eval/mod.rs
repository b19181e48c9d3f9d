//! Evaluation: the metrics the paper reports, computed on our own generated and reference
//! objects. [`generative`] holds NAP's distribution metrics (§7 of method.md); [`guided`] holds
//! PhysNAP's guidance metrics (E_pc, D_pc, E_pen, E_mob, §8.8) and the Table 1 runner; [`real`]
//! holds the real-scan metrics of real-scans.md §3 (generated object against the scanned asset).
//!
//! Why a separate layer: metrics are pure functions of objects, meshes and clouds; they never
//! touch the network or the transports, so the CLI, tests and benchmarks share them.

pub mod generative;
pub mod guided;
pub mod rank;
pub mod real;
pub mod shape_iou;
