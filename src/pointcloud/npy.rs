//! NPY point clouds: an (N, 3) float array read through the crate's one NPY codec
//! ([`crate::io::npy`]), with the point-count limits and error messages of point-cloud input.

#[allow(unused_imports)]
use super::*;
use crate::io::npy::{NpyError, Py, parse_header, read_data};

pub(crate) fn npy_read(bytes: &[u8], limits: &Limits) -> Result<Vec<[f32; 3]>, PointCloudError> {
    let err = |e: NpyError| match e {
        NpyError::Malformed(detail) => mal(NPY, detail),
        NpyError::Truncated {
            expected_bytes,
            got_bytes,
        } => truncated(NPY, expected_bytes, got_bytes),
    };
    let header = parse_header(bytes).map_err(err)?;
    let shape = &header.shape;
    let n = match shape {
        Py::Tuple(dims) => match dims[..] {
            [Py::Int(n), Py::Int(3)] if n >= 0 => n,
            _ => {
                return Err(mal(
                    NPY,
                    format!("header 'shape' is {shape}; expected (N, 3)"),
                ));
            }
        },
        other => {
            return Err(mal(
                NPY,
                format!("header 'shape' is {other}; expected a tuple (N, 3)"),
            ));
        }
    };
    let count = check_count(u64::try_from(n).unwrap_or(u64::MAX), limits)?;
    let flat = read_data(bytes, &header, count, 3).map_err(err)?;
    Ok(flat.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect())
}

pub(crate) fn npy_write(points: &[[f32; 3]]) -> Vec<u8> {
    let flat: Vec<f32> = points.iter().flatten().copied().collect();
    crate::io::npy::to_bytes(points.len(), 3, &flat)
}
