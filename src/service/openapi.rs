//! The OpenAPI document (`openapi.yaml`): the annotations of [`super::http`], made exact.
//!
//! Why it exists: the derive writes types, not rules. This module adds what the server
//! enforces on each field by itself, from the same constants the validation uses (ranges,
//! counts, enumerations, the one-of of the point sources, the page-token pattern), marks the
//! one public operation, and describes the SSE events as JSON schemas. A rule is stated here
//! only when the server enforces exactly it, so a request the document allows is refused only
//! for a rule between fields or inside a payload (a camera outside the cloud's box, `n_g`
//! at most `steps`, a PLY inside base64), which JSON Schema cannot state; those 422s list
//! the field, limit and value. `scripts/ci-schemathesis.sh` holds the server to the document.

use serde_json::{Value, json};
use utoipa::OpenApi as _;

use super::api::{ARTIFACT_NAMES, media_type};
use super::jobs::MAX_PAGE_SIZE;
use super::spec::{Limits, MAX_TAU, SAMPLER_DDIM, SAMPLER_DDPM};
use crate::engine::free_space::MAX_CAMERAS;
use crate::engine::guidance::MAX_REFINE_STEPS;
use crate::engine::sample::MAX_CATEGORY_GUIDANCE;
use crate::engine::schedule::NUM_STEPS;

/// The document as committed in `openapi.yaml` (JSON, which is valid YAML 1.2).
pub fn document() -> String {
    let mut doc =
        serde_json::to_value(super::http::ApiDoc::openapi()).expect("the document serialises");
    refine(&mut doc, &Limits::default());
    let mut s = serde_json::to_string_pretty(&doc).expect("the document serialises");
    s.push('\n');
    s
}

/// Largest finite f32: points are f32 in the engine; larger coordinates are refused.
const MAX_COORDINATE: f64 = f32::MAX as f64;

/// A number as the server reads one (Rust's `f64` parsing, finite forms only).
const NUMBER: &str = r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?";

/// `x,y,z` in a query string.
fn triple_pattern() -> String {
    let n = format!(r"\s*{NUMBER}\s*");
    format!("^{n},{n},{n}$")
}

/// Per-field rules of a job request, by field name (JSON body and upload query string alike).
fn field_rules(l: &Limits) -> Vec<(&'static str, Value)> {
    let weight = json!({"minimum": 0, "maximum": l.max_weight});
    let steps = NUM_STEPS as u64;
    vec![
        ("w_pc", weight.clone()),
        ("w_pen", weight.clone()),
        ("w_mob", weight.clone()),
        ("w_free", weight),
        ("n_g", json!({"minimum": 0, "maximum": steps})),
        ("tau", json!({"exclusiveMinimum": 0, "maximum": MAX_TAU})),
        ("guidance_max_step", json!({"minimum": 0})),
        (
            "refine_steps",
            json!({"minimum": 0, "maximum": MAX_REFINE_STEPS}),
        ),
        (
            "refine_physics_steps",
            json!({"minimum": 0, "maximum": MAX_REFINE_STEPS}),
        ),
        ("eta", json!({"minimum": 0, "maximum": 1})),
        ("steps", json!({"minimum": 1, "maximum": steps})),
        ("seed", json!({"minimum": 0, "maximum": u64::MAX})),
        ("samples", json!({"minimum": 1, "maximum": l.max_samples})),
        (
            "deadline_seconds",
            json!({"exclusiveMinimum": 0, "maximum": l.max_deadline_seconds}),
        ),
        ("preview_every", json!({"minimum": 0, "maximum": steps})),
        (
            "resolution",
            json!({"minimum": l.resolution.0, "maximum": l.resolution.1}),
        ),
        (
            "category_guidance",
            json!({"minimum": 0, "maximum": MAX_CATEGORY_GUIDANCE}),
        ),
        (
            "category_guidance_below",
            json!({"minimum": 1, "maximum": steps}),
        ),
        // "" means the default, as an absent field does.
        ("sampler", json!({"enum": ["", SAMPLER_DDPM, SAMPLER_DDIM]})),
        (
            "retrieval",
            json!({"enum": ["", "auto", "off", "empty", "all", "category"]}),
        ),
        ("joint_motion", json!({"enum": ["", "screw", "dominant"]})),
        ("repair", json!({"enum": ["", "on", "off"]})),
    ]
}

/// The one operation without a token (`GET`; the categories the loaded weights know).
const PUBLIC_PATH: &str = "/v1/categories";

/// `frame`: surrounding white space is ignored; empty is the default.
const FRAME_PATTERN: &str = r"^\s*(canonical|auto)?\s*$";

/// The point sources of a JSON request: exactly one is given (not null).
const POINT_SOURCES: [&str; 4] = [
    "points",
    "points_f32le_base64",
    "points_ply_base64",
    "points_npy_base64",
];

fn merge(into: &mut Value, rules: &Value) {
    if let (Some(into), Some(rules)) = (into.as_object_mut(), rules.as_object()) {
        for (k, v) in rules {
            into.insert(k.clone(), v.clone());
        }
    }
}

/// With `type: [x, "null"]`, an enum must list null too.
fn nullable_enum(schema: &mut Value) {
    let nullable = schema["type"]
        .as_array()
        .is_some_and(|t| t.iter().any(|t| t == "null"));
    if let (true, Some(e)) = (
        nullable,
        schema.get_mut("enum").and_then(Value::as_array_mut),
    ) {
        e.push(Value::Null);
    }
}

fn refine(doc: &mut Value, l: &Limits) {
    let rules = field_rules(l);
    // The JSON request body.
    let req = &mut doc["components"]["schemas"]["JobRequest"];
    for (name, r) in &rules {
        let p = &mut req["properties"][*name];
        merge(p, r);
        nullable_enum(p);
    }
    let b64 = json!({"contentEncoding": "base64", "pattern": "^[A-Za-z0-9+/]*={0,2}$"});
    for name in &POINT_SOURCES[1..] {
        merge(&mut req["properties"][*name], &b64);
    }
    merge(
        &mut req["properties"]["points"],
        &json!({
            "minItems": l.min_points,
            "maxItems": l.max_points,
            "items": {"type": "array", "minItems": 3, "maxItems": 3,
                      "items": {"type": "number", "minimum": -MAX_COORDINATE, "maximum": MAX_COORDINATE}}
        }),
    );
    merge(
        &mut req["properties"]["up"],
        &json!({"minItems": 3, "maxItems": 3}),
    );
    req["additionalProperties"] = json!(false);
    req["oneOf"] = Value::Array(
        POINT_SOURCES
            .iter()
            .map(|given| {
                let mut props = serde_json::Map::new();
                for other in POINT_SOURCES.iter().filter(|o| *o != given) {
                    props.insert(other.to_string(), json!({"type": "null"}));
                }
                props.insert(given.to_string(), json!({"not": {"type": "null"}}));
                json!({"required": [given], "properties": props})
            })
            .collect(),
    );

    merge(
        &mut req["properties"]["frame"],
        &json!({"pattern": FRAME_PATTERN}),
    );

    let paths = doc["paths"].as_object_mut().expect("paths");
    // The upload's query parameters take the same rules.
    if let Some(params) = paths["/v1/jobs"]["post"]["parameters"].as_array_mut() {
        for p in params {
            let name = p["name"].as_str().unwrap_or_default().to_string();
            if let Some((_, r)) = rules.iter().find(|(n, _)| *n == name) {
                merge(&mut p["schema"], r);
            }
            match name.as_str() {
                "camera" => merge(
                    &mut p["schema"],
                    &json!({"maxItems": MAX_CAMERAS, "items": {"type": "string", "pattern": triple_pattern()}}),
                ),
                "up" => merge(&mut p["schema"], &json!({"pattern": triple_pattern()})),
                "frame" => merge(&mut p["schema"], &json!({"pattern": FRAME_PATTERN})),
                _ => {}
            }
        }
    }
    // The list's paging.
    if let Some(params) = paths["/v1/jobs"]["get"]["parameters"].as_array_mut() {
        for p in params {
            match p["name"].as_str() {
                Some("page_size") => merge(
                    &mut p["schema"],
                    &json!({"minimum": 1, "maximum": MAX_PAGE_SIZE}),
                ),
                // base64url("after:" + id): see `jobs::decode_token`.
                Some("page_token") => merge(
                    &mut p["schema"],
                    &json!({"pattern": "^(YWZ0ZXI6([A-Za-z0-9_-]{4})*)?$"}),
                ),
                _ => {}
            }
        }
    }
    if let Some(params) = paths["/v1/jobs/{id}/events"]["get"]["parameters"].as_array_mut() {
        for p in params {
            if p["name"] == "after" || p["name"] == "Last-Event-ID" {
                merge(&mut p["schema"], &json!({"maximum": i64::MAX}));
            }
        }
    }
    if let Some(params) =
        paths["/v1/jobs/{id}/artifacts/{name}"]["get"]["parameters"].as_array_mut()
    {
        for p in params {
            if p["name"] == "name" {
                merge(&mut p["schema"], &json!({"enum": ARTIFACT_NAMES}));
            }
        }
    }
    // One media type per artefact kind, the one the server sends (`media_type`).
    let mut content = serde_json::Map::new();
    for name in ARTIFACT_NAMES {
        let schema = match media_type(name) {
            "application/json" => json!({"type": "object"}),
            _ => json!({"type": "string", "format": "binary"}),
        };
        content.insert(media_type(name).to_string(), json!({ "schema": schema }));
    }
    paths["/v1/jobs/{id}/artifacts/{name}"]["get"]["responses"]["200"]["content"] =
        Value::Object(content);
    // Every operation but the one public one needs a token, and answers 401 without one.
    for (path, ops) in paths.iter_mut() {
        for op in ops.as_object_mut().into_iter().flat_map(|o| o.values_mut()) {
            if path == PUBLIC_PATH {
                op["security"] = json!([]);
            } else {
                op["responses"]["401"] = json!({
                    "description": "Missing or unknown bearer token",
                    "content": {"application/problem+json": {"schema": {"$ref": "#/components/schemas/Problem"}}}
                });
            }
        }
    }
    // The SSE stream, event by event: `data` is a JSON document of the kind's schema.
    let event = |kind: &str, data: Value| {
        json!({
            "type": "object",
            "required": ["event", "data"],
            "properties": {
                "id": {"type": "string", "pattern": "^[0-9]+$"},
                "event": {"const": kind},
                "data": {"type": "string", "contentMediaType": "application/json", "contentSchema": data}
            }
        })
    };
    let schema = |name: &str| json!({"$ref": format!("#/components/schemas/{name}")});
    let sse = &mut paths["/v1/jobs/{id}/events"]["get"]["responses"]["200"];
    sse["description"] = json!(
        "text/event-stream. Each event has `id` (the last persisted sequence), `event` (its \
         kind) and `data`, one JSON document: the job for `state` and `done`, the progress for \
         `progress`, the artefact for `artifact`, `{}` for `shutdown`"
    );
    sse["content"]["text/event-stream"]["schema"] = json!({"oneOf": [
        event("state", schema("JobView")),
        event("progress", schema("ProgressView")),
        event("artifact", schema("ArtifactView")),
        event("done", schema("JobView")),
        event("shutdown", json!({"type": "object", "maxProperties": 0})),
    ]});
}
