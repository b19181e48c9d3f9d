//! JSON point clouds: `[[x, y, z], ...]` or `{"points": [...]}`.

#[allow(unused_imports)]
use super::*;
use std::fmt::Write as _;

// ---------------------------------------------------------------------------------------------
// JSON

pub(crate) fn json_kind(v: &serde_json::Value) -> String {
    use serde_json::Value;
    match v {
        Value::Null => "null".to_string(),
        Value::Bool(b) => format!("a boolean ({b})"),
        Value::Number(n) => format!("a number ({n})"),
        Value::String(s) => format!("a string (\"{}\")", snippet(s.as_bytes())),
        Value::Array(a) => format!("an array of {} values", a.len()),
        Value::Object(_) => "an object".to_string(),
    }
}

pub(crate) fn json_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
    use serde_json::Value;
    let value: Value =
        serde_json::from_slice(bytes).map_err(|e| mal(JSON, format!("not valid JSON: {e}")))?;
    let expected = "an array of [x, y, z] arrays or an object with a 'points' array";
    let list = match &value {
        Value::Array(list) => list,
        Value::Object(map) => match map.get("points") {
            Some(Value::Array(list)) => list,
            Some(other) => {
                return Err(mal(
                    JSON,
                    format!(
                        "'points' is {}; expected an array of [x, y, z] arrays",
                        json_kind(other)
                    ),
                ));
            }
            None => {
                let keys: Vec<&str> = map.keys().take(8).map(String::as_str).collect();
                return Err(mal(
                    JSON,
                    format!(
                        "object has no 'points' key (keys: {}); expected {expected}",
                        snippet(keys.join(", ").as_bytes())
                    ),
                ));
            }
        },
        other => {
            return Err(mal(
                JSON,
                format!(
                    "top-level value is {}; expected {expected}",
                    json_kind(other)
                ),
            ));
        }
    };
    let count = check_count(list.len() as u64, limits)?;
    let mut points = Vec::with_capacity(count);
    for (i, item) in list.iter().enumerate() {
        let Value::Array(coords) = item else {
            let hint = if item.is_number() {
                " (flat arrays of numbers are not accepted; group them as [[x, y, z], ...])"
            } else {
                ""
            };
            return Err(mal(
                JSON,
                format!(
                    "points[{i}] is {}, expected an [x, y, z] array{hint}",
                    json_kind(item)
                ),
            ));
        };
        if coords.len() != 3 {
            return Err(mal(
                JSON,
                format!("points[{i}] has {} values, expected 3", coords.len()),
            ));
        }
        let mut p = [0f32; 3];
        for (axis, (v, c)) in p.iter_mut().zip(coords).enumerate() {
            let Some(x) = c.as_f64() else {
                return Err(mal(
                    JSON,
                    format!("points[{i}][{axis}] is {}, expected a number", json_kind(c)),
                ));
            };
            // Out of f32 range becomes ±inf here, which validate reports as NonFinite.
            *v = x as f32;
        }
        points.push(p);
    }
    Ok(points)
}

/// Appends `v` as a JSON number that reads back (as f64, then cast to f32) to exactly `v`:
/// the short f32 form when that round-trips, else the exact f64 form. Non-finite → `null`.
pub(crate) fn json_number(out: &mut String, v: f32) {
    if !v.is_finite() {
        out.push_str("null");
        return;
    }
    let start = out.len();
    let _ = write!(out, "{v:?}");
    let exact = out[start..]
        .parse::<f64>()
        .is_ok_and(|back| (back as f32).to_bits() == v.to_bits());
    if !exact {
        out.truncate(start);
        let _ = write!(out, "{:?}", f64::from(v));
    }
}

pub(crate) fn json_write(points: &[[f32; 3]]) -> Vec<u8> {
    let mut out = String::with_capacity(16 + points.len() * 40);
    out.push_str("{\"points\":[");
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        out.push('[');
        for (axis, &v) in p.iter().enumerate() {
            if axis > 0 {
                out.push(',');
            }
            json_number(&mut out, v);
        }
        out.push(']');
    }
    out.push_str("]}");
    out.into_bytes()
}
