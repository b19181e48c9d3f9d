//! Minimal NPY (NumPy array file) writer and reader for 2-D little-endian f32 arrays.
//!
//! Why it exists: training data (graph records, SDF samples, surface points) is stored as NPY
//! so it can be inspected with NumPy, and read back by the trainers without a parser
//! dependency. Version 1.0 headers, `<f4`, C order; the data starts at a multiple of 64 bytes.
//! (User point clouds go through `crate::pointcloud`, which also reads f64/big-endian files.)

use std::path::Path;

use super::FormatError;

/// Serialise a `rows × cols` f32 array.
pub fn to_bytes(rows: usize, cols: usize, data: &[f32]) -> Vec<u8> {
    debug_assert_eq!(rows * cols, data.len());
    let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({rows}, {cols}), }}");
    let unpadded = 10 + dict.len() + 1;
    let total = unpadded.div_ceil(64) * 64;
    let mut header = dict.into_bytes();
    header.resize(total - 10 - 1, b' ');
    header.push(b'\n');
    let mut out = Vec::with_capacity(total + data.len() * 4);
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(&header);
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Parse a 2-D `<f4` C-order array: `(rows, cols, data)`.
pub fn from_bytes(bytes: &[u8]) -> Result<(usize, usize, Vec<f32>), String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not an NPY file (bad magic)".into());
    }
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported NPY version {v}")),
    };
    let header = bytes
        .get(start..start + hlen)
        .ok_or("truncated NPY header")?;
    let header = std::str::from_utf8(header).map_err(|_| "NPY header is not UTF-8")?;
    if !header.contains("'<f4'") {
        return Err(format!("NPY dtype must be '<f4': {}", header.trim()));
    }
    if header.contains("'fortran_order': True") {
        return Err("NPY fortran_order arrays are not supported".into());
    }
    let shape = header
        .split("'shape':")
        .nth(1)
        .and_then(|s| s.split(')').next())
        .map(|s| s.trim().trim_start_matches('('))
        .ok_or("NPY header has no shape")?;
    let dims: Vec<usize> = shape
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| format!("bad NPY shape ({shape})"))
        })
        .collect::<Result<_, _>>()?;
    let (rows, cols) = match dims[..] {
        [r, c] => (r, c),
        [r] => (r, 1),
        _ => return Err(format!("NPY shape must be 2-D, got ({shape})")),
    };
    let data = &bytes[start + hlen..];
    let need = rows
        .checked_mul(cols)
        .and_then(|n| n.checked_mul(4))
        .ok_or("NPY shape overflows")?;
    if data.len() < need {
        return Err(format!(
            "truncated NPY data: need {need} bytes, got {}",
            data.len()
        ));
    }
    let values = data[..need]
        .chunks_exact(4)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    Ok((rows, cols, values))
}

/// Write a `rows × cols` f32 array to `path`.
pub fn write(path: &Path, rows: usize, cols: usize, data: &[f32]) -> Result<(), FormatError> {
    std::fs::write(path, to_bytes(rows, cols, data)).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })
}

/// Read a 2-D f32 array from `path`.
pub fn read(path: &Path) -> Result<(usize, usize, Vec<f32>), FormatError> {
    let bytes = std::fs::read(path).map_err(|source| FormatError::Io {
        path: path.display().to_string(),
        source,
    })?;
    from_bytes(&bytes).map_err(|message| FormatError::Malformed {
        what: "NPY array",
        path: path.display().to_string(),
        message,
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn round_trip_and_alignment() {
        let data: Vec<f32> = (0..12).map(|v| v as f32 * 0.5 - 1.0).collect();
        let b = super::to_bytes(3, 4, &data);
        let hlen = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + hlen) % 64, 0);
        assert_eq!(super::from_bytes(&b).unwrap(), (3, 4, data));
        assert!(
            super::from_bytes(&b[..b.len() - 1])
                .unwrap_err()
                .contains("truncated")
        );
        assert!(super::from_bytes(b"hello world").is_err());
    }
}
