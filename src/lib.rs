//! physnap: physically plausible articulated-object generation (PhysNAP, Kreber & Stueckler,
//! ICCV 2025) as a library, a CLI and (later) a service.
//!
//! Start reading at ARCHITECTURE.md. The core types are [`object::ArticulatedObject`] (what
//! users get) and [`graph::GraphTensor`] (what the diffusion model sees).

pub mod data;
pub mod engine;
pub mod error;
pub mod eval;
pub mod export;
pub mod fixtures;
pub mod frame;
pub mod graph;
pub mod io;
pub mod kinematics;
pub mod mesh;
pub mod model;
pub mod object;
pub mod pointcloud;
pub mod render;
pub mod service;
pub mod shape;
pub mod sim;
pub mod train;

pub use error::{CoreError, CoreResult};
pub use graph::GraphTensor;
pub use object::{ArticulatedObject, Joint, JointKind, JointState, Part};
pub use shape::{PartShape, Primitive, Sdf};
