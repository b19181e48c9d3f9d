//! The inference service: asynchronous generation jobs over REST (+ SSE) and gRPC.
//!
//! Why it exists: a generation takes minutes on a CPU, so clients submit *jobs* and watch them
//! instead of holding a request open (`../shared/spec/service.md`). Layers, outermost first:
//!
//! - [`server`]: `physnap serve` — listeners, graceful drain.
//! - [`http`] (axum, problem+json, SSE, admin, OpenAPI) and [`grpc`] (tonic): thin adapters;
//!   [`openapi`]: the OpenAPI document, with the rules the server enforces.
//! - [`api`]: the JSON wire types shared by both; [`auth`]: bearer-token tenants.
//! - [`jobs`]: the [`jobs::Service`] core — admission, bounded queue, worker pool, events.
//! - [`store`]: the durable SQLite job store; [`spec`]: the validated domain [`spec::JobSpec`].
//! - [`runner`]: the single engine-facing function, [`runner::run_job`].
//!
//! The engine never sees a wire type: every request becomes a [`spec::JobSpec`] first.

pub mod api;
pub mod auth;
pub mod grpc;
pub mod http;
pub mod jobs;
pub mod openapi;
pub mod queue;
pub mod runner;
pub mod server;
pub mod spec;
pub mod store;
