//! Tests of the point-cloud readers and writers on good and hostile input.

use super::*;
use crate::io::npy::NPY_MAGIC;
use proptest::prelude::*;
use std::fmt::Write as _;
use std::time::{Duration, Instant};

const ALL: [Format; 4] = [Format::Ply, Format::PlyAscii, Format::Npy, Format::Json];

fn sample() -> PointCloud {
    PointCloud {
        points: vec![
            [0.0, 0.0, 0.0],
            [0.1, -0.2, 0.3],
            [1.5e-7, -3.25e5, 12.0],
            [-0.0, 1.0 / 3.0, f32::MAX],
            [f32::MIN_POSITIVE, -f32::MIN_POSITIVE / 4.0, 1e-45],
        ],
    }
}

fn bits(points: &[[f32; 3]]) -> Vec<[u32; 3]> {
    points.iter().map(|p| p.map(f32::to_bits)).collect()
}

/// Asserts the error kind and that the message contains every needle.
#[track_caller]
fn expect_err(res: Result<PointCloud, PointCloudError>, kind: &str, needles: &[&str]) {
    let err = match res {
        Ok(c) => panic!(
            "expected a {kind} error, got Ok with {} points",
            c.points.len()
        ),
        Err(e) => e,
    };
    let msg = err.to_string();
    assert_eq!(err.error_type(), kind, "wrong kind for: {msg}");
    for needle in needles {
        assert!(msg.contains(needle), "message {msg:?} lacks {needle:?}");
    }
}

fn read(bytes: &[u8], format: Format) -> Result<PointCloud, PointCloudError> {
    PointCloud::from_bytes(bytes, format, &Limits::default())
}

fn binary_ply(encoding: &str, props: &str, count: u64, body: &[u8]) -> Vec<u8> {
    let mut out =
        format!("ply\nformat {encoding} 1.0\nelement vertex {count}\n{props}end_header\n")
            .into_bytes();
    out.extend_from_slice(body);
    out
}

const XYZ_FLOAT: &str = "property float x\nproperty float y\nproperty float z\n";

fn le_f32s(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn npy(descr: &str, fortran: bool, shape: &str, body: &[u8]) -> Vec<u8> {
    let fo = if fortran { "True" } else { "False" };
    let header = format!("{{'descr': '{descr}', 'fortran_order': {fo}, 'shape': {shape}, }}\n");
    let mut out = NPY_MAGIC.to_vec();
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(body);
    out
}

#[test]
fn round_trip_every_format_bit_exact() {
    let cloud = sample();
    for format in ALL {
        let bytes = cloud.to_bytes(format);
        let back = read(&bytes, format).unwrap_or_else(|e| panic!("{format:?}: {e}"));
        assert_eq!(bits(&back.points), bits(&cloud.points), "{format:?}");
    }
}

#[test]
fn file_round_trip_is_atomic_and_leaves_no_temp_file() {
    let dir = tempfile::tempdir().unwrap();
    let cloud = sample();
    for (name, format) in [
        ("a.ply", Format::Ply),
        ("b.PLY", Format::PlyAscii),
        ("c.npy", Format::Npy),
        ("d.Json", Format::Json),
    ] {
        let path = dir.path().join(name);
        cloud.write(&path, format).unwrap();
        // Overwriting goes through the same temp + rename path.
        cloud.write(&path, format).unwrap();
        let back = PointCloud::read(&path, &Limits::default()).unwrap();
        assert_eq!(back, cloud, "{name}");
    }
    let mut names: Vec<String> = fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names, ["a.ply", "b.PLY", "c.npy", "d.Json"]);
}

#[test]
fn write_into_missing_directory_is_io_error_naming_the_path() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("missing").join("x.ply");
    let err = sample().write(&path, Format::Ply).unwrap_err();
    assert_eq!(err.error_type(), "io");
    assert!(err.to_string().contains("missing"), "{err}");
}

#[test]
fn read_errors_for_unknown_extension_and_missing_file() {
    let err = PointCloud::read(Path::new("cloud.xyz"), &Limits::default()).unwrap_err();
    assert_eq!(err.error_type(), "unknown_format");
    assert!(err.to_string().contains("cloud.xyz"), "{err}");
    let err = PointCloud::read(Path::new("/nonexistent/c.ply"), &Limits::default()).unwrap_err();
    assert_eq!(err.error_type(), "io");
    assert!(err.to_string().contains("/nonexistent/c.ply"), "{err}");
}

#[test]
fn format_from_path() {
    assert_eq!(Format::from_path(Path::new("a/b.ply")), Some(Format::Ply));
    assert_eq!(Format::from_path(Path::new("b.PlY")), Some(Format::Ply));
    assert_eq!(Format::from_path(Path::new("b.NPY")), Some(Format::Npy));
    assert_eq!(Format::from_path(Path::new("b.json")), Some(Format::Json));
    assert_eq!(Format::from_path(Path::new("b.txt")), None);
    assert_eq!(Format::from_path(Path::new("ply")), None);
}

#[test]
fn npy_f64_big_endian_fortran_and_v2() {
    let pts = [[1.0f64, 2.0, 3.0], [-4.5, 5.25, 1e-3]];
    let expect: Vec<[f32; 3]> = pts.iter().map(|p| p.map(|v| v as f32)).collect();
    let le8: Vec<u8> = pts.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
    let c = read(&npy("<f8", false, "(2, 3)", &le8), Format::Npy).unwrap();
    assert_eq!(c.points, expect);
    let be8: Vec<u8> = pts.iter().flatten().flat_map(|v| v.to_be_bytes()).collect();
    let c = read(&npy(">f8", false, "(2, 3)", &be8), Format::Npy).unwrap();
    assert_eq!(c.points, expect);
    let be4: Vec<u8> = expect
        .iter()
        .flatten()
        .flat_map(|v| v.to_be_bytes())
        .collect();
    let c = read(&npy(">f4", false, "(2, 3)", &be4), Format::Npy).unwrap();
    assert_eq!(c.points, expect);
    // Fortran order: all x, then all y, then all z.
    let cols: Vec<f32> = (0..3)
        .flat_map(|a| expect.iter().map(move |p| p[a]))
        .collect();
    let c = read(&npy("<f4", true, "(2, 3)", &le_f32s(&cols)), Format::Npy).unwrap();
    assert_eq!(c.points, expect);
    // Version 2.0: 4-byte header length, double quotes, Python 2 long ints.
    let header = "{\"descr\": \"<f4\", \"fortran_order\": False, \"shape\": (2L, 3L)}\n";
    let mut v2 = NPY_MAGIC.to_vec();
    v2.extend_from_slice(&[2, 0]);
    v2.extend_from_slice(&(header.len() as u32).to_le_bytes());
    v2.extend_from_slice(header.as_bytes());
    v2.extend_from_slice(&le_f32s(expect.as_flattened()));
    assert_eq!(read(&v2, Format::Npy).unwrap().points, expect);
}

#[test]
fn npy_written_layout_matches_numpy() {
    let bytes = sample().to_bytes(Format::Npy);
    assert_eq!(&bytes[..8], b"\x93NUMPY\x01\x00");
    let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let data_start = 10 + header_len;
    assert_eq!(data_start % 64, 0);
    assert_eq!(bytes[data_start - 1], b'\n');
    let header = std::str::from_utf8(&bytes[10..data_start]).unwrap();
    assert!(header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (5, 3), }"));
    assert_eq!(bytes.len(), data_start + 5 * 12);
}

#[test]
fn big_endian_binary_ply_with_mixed_types() {
    // x double, an int we skip, y float, z short (integers are converted).
    let props = "property double x\nproperty int id\nproperty float y\nproperty short z\n";
    let mut body = Vec::new();
    for (x, id, y, z) in [(1.5f64, 7i32, -2.25f32, 3i16), (-0.5, 8, 4.0, -9)] {
        body.extend_from_slice(&x.to_be_bytes());
        body.extend_from_slice(&id.to_be_bytes());
        body.extend_from_slice(&y.to_be_bytes());
        body.extend_from_slice(&z.to_be_bytes());
    }
    let c = read(
        &binary_ply("binary_big_endian", props, 2, &body),
        Format::Ply,
    )
    .unwrap();
    assert_eq!(c.points, vec![[1.5, -2.25, 3.0], [-0.5, 4.0, -9.0]]);
}

#[test]
fn ascii_ply_with_extra_properties_and_faces_after_vertices() {
    let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info scanner 3\r\n\
        element vertex 3\r\nproperty float32 x\r\nproperty float32 y\r\nproperty float32 z\r\n\
        property float nx\r\nproperty float ny\r\nproperty float nz\r\n\
        property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n\
        element face 1\r\nproperty list uchar int vertex_indices\r\nend_header\r\n\
        0 0 0 0 0 1 255 0 0\r\n1 0 0 0 0 1 0 255 0\r\n\r\n0 1 0.5 0 0 1 0 0 255\r\n\
        3 0 1 2\r\n";
    let c = read(text.as_bytes(), Format::PlyAscii).unwrap();
    assert_eq!(
        c.points,
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]]
    );
}

#[test]
fn binary_ply_with_face_after_vertices() {
    let props = format!("{XYZ_FLOAT}element face 1\nproperty list uchar int vertex_indices\n");
    let mut body = le_f32s(&[1.0, 2.0, 3.0]);
    body.extend_from_slice(&[3, 0, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0]);
    let c = read(
        &binary_ply("binary_little_endian", &props, 1, &body),
        Format::Ply,
    )
    .unwrap();
    assert_eq!(c.points, vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn ply_properties_in_order_z_y_x() {
    let props = "property float z\nproperty float y\nproperty float x\n";
    let body = le_f32s(&[3.0, 2.0, 1.0, 6.0, 5.0, 4.0]);
    let c = read(
        &binary_ply("binary_little_endian", props, 2, &body),
        Format::Ply,
    )
    .unwrap();
    assert_eq!(c.points, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
    let text = format!("ply\nformat ascii 1.0\nelement vertex 1\n{props}end_header\n3 2 1\n");
    let c = read(text.as_bytes(), Format::Ply).unwrap();
    assert_eq!(c.points, vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn elements_before_vertex() {
    // Binary: a scalar-only element before vertex is skipped by size.
    let text = format!(
        "ply\nformat binary_little_endian 1.0\nelement camera 2\nproperty double fx\n\
         property uchar flag\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
    );
    let mut bytes = text.into_bytes();
    bytes.extend_from_slice(&[0xAB; 18]);
    bytes.extend_from_slice(&le_f32s(&[7.0, 8.0, 9.0]));
    assert_eq!(
        read(&bytes, Format::Ply).unwrap().points,
        vec![[7.0, 8.0, 9.0]]
    );
    // Binary with a list property before vertex: clear error naming element and property.
    let text = format!(
        "ply\nformat binary_little_endian 1.0\nelement face 1\n\
         property list uchar int vertex_indices\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
    );
    expect_err(
        read(text.as_bytes(), Format::Ply),
        "malformed",
        &["'face'", "'vertex_indices'", "before 'vertex'"],
    );
    // Ascii: any element before vertex is skipped line by line.
    let text = format!(
        "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
         element vertex 1\n{XYZ_FLOAT}end_header\n3 0 1 2\n7 8 9\n"
    );
    assert_eq!(
        read(text.as_bytes(), Format::Ply).unwrap().points,
        vec![[7.0, 8.0, 9.0]]
    );
}

#[test]
fn ply_header_errors_name_the_problem() {
    expect_err(
        read(b"plx\nformat ascii 1.0\n", Format::Ply),
        "malformed",
        &["'ply' magic", "plx"],
    );
    expect_err(read(b"", Format::Ply), "malformed", &["'ply' magic"]);
    let unknown =
        format!("ply\nformat binary_middle_endian 1.0\nelement vertex 1\n{XYZ_FLOAT}end_header\n");
    expect_err(
        read(unknown.as_bytes(), Format::Ply),
        "malformed",
        &["header line 2", "unknown format 'binary_middle_endian'"],
    );
    let no_end = format!("ply\nformat ascii 1.0\nelement vertex 1\n{XYZ_FLOAT}0 0 0\n");
    expect_err(
        read(no_end.as_bytes(), Format::Ply),
        "malformed",
        &["header line 7", "unknown keyword '0'", "end_header"],
    );
    let header_only = format!("ply\nformat ascii 1.0\nelement vertex 1\n{XYZ_FLOAT}");
    expect_err(
        read(header_only.as_bytes(), Format::Ply),
        "malformed",
        &["no 'end_header' line", "after line 6"],
    );
    let no_y = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float z\nend_header\n0 0\n";
    expect_err(
        read(no_y.as_bytes(), Format::Ply),
        "malformed",
        &["no 'y' property", "found: x, z"],
    );
    let bad_count = format!("ply\nformat ascii 1.0\nelement vertex abc\n{XYZ_FLOAT}end_header\n");
    expect_err(
        read(bad_count.as_bytes(), Format::Ply),
        "malformed",
        &[
            "header line 3",
            "element vertex count 'abc' is not an integer",
        ],
    );
    let neg_count = format!("ply\nformat ascii 1.0\nelement vertex -4\n{XYZ_FLOAT}end_header\n");
    expect_err(
        read(neg_count.as_bytes(), Format::Ply),
        "malformed",
        &["'-4' is negative"],
    );
    let bad_type = "ply\nformat ascii 1.0\nelement vertex 1\nproperty half x\nend_header\n";
    expect_err(
        read(bad_type.as_bytes(), Format::Ply),
        "malformed",
        &["header line 4", "'half'", "'x'"],
    );
    let no_vertex = "ply\nformat ascii 1.0\nelement face 0\nend_header\n";
    expect_err(
        read(no_vertex.as_bytes(), Format::Ply),
        "malformed",
        &["no 'vertex' element"],
    );
    let no_format = format!("ply\nelement vertex 1\n{XYZ_FLOAT}end_header\n0 0 0\n");
    expect_err(
        read(no_format.as_bytes(), Format::Ply),
        "malformed",
        &["no 'format' line"],
    );
    let keyword = "ply\nformat ascii 1.0\nfrobnicate 3\nend_header\n";
    expect_err(
        read(keyword.as_bytes(), Format::Ply),
        "malformed",
        &["header line 3", "'frobnicate'"],
    );
}

#[test]
fn ply_ascii_data_errors_name_the_line() {
    let head = format!("ply\nformat ascii 1.0\nelement vertex 2\n{XYZ_FLOAT}end_header\n");
    let short = format!("{head}0 0 0\n1 2\n");
    expect_err(
        read(short.as_bytes(), Format::Ply),
        "malformed",
        &["line 9", "vertex 1 has 2 values, expected 3"],
    );
    let word = format!("{head}0 0 0\n1 two 3\n");
    expect_err(
        read(word.as_bytes(), Format::Ply),
        "malformed",
        &["line 9", "property 'y' value 'two' is not a number"],
    );
    let ended = format!("{head}0 0 0\n");
    expect_err(
        read(ended.as_bytes(), Format::Ply),
        "malformed",
        &["after 1 of 2 'vertex' lines"],
    );
    let nan = format!("{head}0 0 0\n1 2 nan\n");
    expect_err(
        read(nan.as_bytes(), Format::Ply),
        "non_finite",
        &["point 1", "z coordinate", "NaN"],
    );
}

#[test]
fn truncated_binary_ply_reports_expected_and_got_bytes() {
    let body = le_f32s(&[1.0, 2.0, 3.0, 4.0, 5.0]); // 20 of 24 bytes
    let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, 2, &body);
    let header_len = bytes.len() - 20;
    let need = (header_len + 24).to_string();
    let got = bytes.len().to_string();
    expect_err(
        read(&bytes, Format::Ply),
        "truncated",
        &["PLY", &need, &got],
    );
}

#[test]
fn non_finite_points_name_index_and_axis() {
    let body = le_f32s(&[0.0, 0.0, 0.0, 1.0, f32::NAN, 2.0]);
    let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, 2, &body);
    expect_err(
        read(&bytes, Format::Ply),
        "non_finite",
        &["point 1 has a non-finite y coordinate (NaN)"],
    );
    let npy_bytes = npy(
        "<f4",
        false,
        "(2, 3)",
        &le_f32s(&[0.0, 0.0, 0.0, 1.0, 1.0, f32::NAN]),
    );
    expect_err(
        read(&npy_bytes, Format::Npy),
        "non_finite",
        &["point 1 has a non-finite z coordinate (NaN)"],
    );
    let body = le_f32s(&[f32::INFINITY, 0.0, 0.0]);
    let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, 1, &body);
    expect_err(
        read(&bytes, Format::Ply),
        "non_finite",
        &["point 0 has a non-finite x coordinate (inf)"],
    );
    let cloud = PointCloud {
        points: vec![[0.0; 3], [0.0; 3], [f32::NEG_INFINITY, 0.0, 0.0]],
    };
    for format in [Format::Ply, Format::PlyAscii, Format::Npy] {
        expect_err(
            read(&cloud.to_bytes(format), format),
            "non_finite",
            &["point 2", "x coordinate", "-inf"],
        );
    }
    // JSON cannot hold inf: it is written as null and rejected by the reader.
    expect_err(
        read(&cloud.to_bytes(Format::Json), Format::Json),
        "malformed",
        &["points[2][0] is null"],
    );
    // Out of f32 range in JSON.
    expect_err(
        read(br#"[[0, 0, 0], [0, 1e39, 0]]"#, Format::Json),
        "non_finite",
        &["point 1 has a non-finite y coordinate (inf)"],
    );
}

#[test]
fn empty_and_limits() {
    let empty_ply = binary_ply("binary_little_endian", XYZ_FLOAT, 0, &[]);
    expect_err(read(&empty_ply, Format::Ply), "empty", &["0 points"]);
    expect_err(
        read(&npy("<f4", false, "(0, 3)", &[]), Format::Npy),
        "empty",
        &["empty"],
    );
    expect_err(read(b"{\"points\": []}", Format::Json), "empty", &["empty"]);
    expect_err(
        PointCloud::default()
            .validate(&Limits::default())
            .map(|()| PointCloud::default()),
        "empty",
        &[],
    );
    let limits = Limits {
        min_points: 10,
        max_points: 3,
    };
    let few = PointCloud {
        points: vec![[0.0; 3]; 2],
    };
    let err = few.validate(&limits).unwrap_err();
    assert_eq!(err.error_type(), "too_few");
    assert_eq!(err.to_string(), "too few points: 2 (minimum 10)");
    let limits = Limits {
        min_points: 1,
        max_points: 3,
    };
    let many = PointCloud {
        points: vec![[0.0; 3]; 4],
    };
    let err = many.validate(&limits).unwrap_err();
    assert_eq!(err.error_type(), "too_many");
    assert_eq!(err.to_string(), "too many points: 4 (limit 3)");
    for format in ALL {
        let res = PointCloud::from_bytes(&many.to_bytes(format), format, &limits);
        expect_err(res, "too_many", &["4", "limit 3"]);
    }
}

#[test]
fn huge_claimed_counts_fail_fast_without_allocating() {
    let start = Instant::now();
    let claim: u64 = 1_000_000_000_000;
    let body = le_f32s(&[1.0, 2.0, 3.0]);
    for enc in ["binary_little_endian", "binary_big_endian", "ascii"] {
        let bytes = binary_ply(enc, XYZ_FLOAT, claim, &body);
        expect_err(
            read(&bytes, Format::Ply),
            "too_many",
            &["1000000000000", "limit 10000000"],
        );
    }
    let npy_bytes = npy("<f4", false, "(1000000000000, 3)", &body);
    expect_err(
        read(&npy_bytes, Format::Npy),
        "too_many",
        &["1000000000000"],
    );
    // With no limit at all the readers must still not trust the header.
    let open = Limits {
        min_points: 1,
        max_points: usize::MAX,
    };
    let bytes = binary_ply("binary_little_endian", XYZ_FLOAT, claim, &body);
    let res = PointCloud::from_bytes(&bytes, Format::Ply, &open);
    expect_err(res, "truncated", &["12000000000", &bytes.len().to_string()]);
    let bytes = binary_ply("ascii", XYZ_FLOAT, claim, b"1 2 3\n");
    let res = PointCloud::from_bytes(&bytes, Format::Ply, &open);
    expect_err(
        res,
        "malformed",
        &["after 1 of 1000000000000 'vertex' lines"],
    );
    let res = PointCloud::from_bytes(&npy_bytes, Format::Npy, &open);
    expect_err(res, "truncated", &["12000000000"]);
    let before = format!(
        "ply\nformat binary_little_endian 1.0\nelement junk 18446744073709551615\n\
         property double a\nelement vertex 1\n{XYZ_FLOAT}end_header\n"
    );
    let res = PointCloud::from_bytes(before.as_bytes(), Format::Ply, &open);
    expect_err(res, "truncated", &[]);
    assert!(
        start.elapsed() < Duration::from_secs(2),
        "took {:?}",
        start.elapsed()
    );
}

#[test]
fn hostile_headers_stay_linear() {
    // 200k properties / elements: a quadratic duplicate check would take minutes.
    let mut h = String::from("ply\nformat binary_little_endian 1.0\nelement vertex 1\n");
    for i in 0..200_000 {
        let _ = writeln!(h, "property uchar p{i}");
    }
    h.push_str(XYZ_FLOAT);
    for i in 0..100_000 {
        let _ = writeln!(h, "element e{i} 5");
    }
    h.push_str("end_header\n");
    let start = Instant::now();
    let res = read(h.as_bytes(), Format::Ply);
    expect_err(res, "truncated", &[]);
    assert!(
        start.elapsed() < Duration::from_secs(5),
        "took {:?}",
        start.elapsed()
    );
    let dup =
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float x\nend_header\n";
    expect_err(
        read(dup.as_bytes(), Format::Ply),
        "malformed",
        &["header line 5", "second property 'x'"],
    );
    let two = format!(
        "ply\nformat ascii 1.0\nelement vertex 1\n{XYZ_FLOAT}element vertex 1\nend_header\n"
    );
    expect_err(
        read(two.as_bytes(), Format::Ply),
        "malformed",
        &["header line 7", "second 'vertex'"],
    );
}

#[test]
fn npy_errors_name_the_problem() {
    let body = le_f32s(&[1.0, 2.0, 3.0, 4.0, 5.0]);
    let bytes = npy("<f4", false, "(2, 3)", &body);
    let need = (bytes.len() - 20 + 24).to_string();
    expect_err(
        read(&bytes, Format::Npy),
        "truncated",
        &["NPY", &need, &bytes.len().to_string()],
    );
    expect_err(
        read(&npy("<i4", false, "(2, 3)", &body), Format::Npy),
        "malformed",
        &["'descr' is '<i4'"],
    );
    expect_err(
        read(&npy("<f4", false, "(3, 2)", &body), Format::Npy),
        "malformed",
        &["'shape' is (3, 2)", "expected (N, 3)"],
    );
    expect_err(
        read(&npy("<f4", false, "(3,)", &body), Format::Npy),
        "malformed",
        &["'shape' is (3,)"],
    );
    expect_err(
        read(&npy("<f4", false, "(1, 3, 1)", &body), Format::Npy),
        "malformed",
        &["(1, 3, 1)"],
    );
    expect_err(
        read(b"\x93NUMPX\x01\x00", Format::Npy),
        "malformed",
        &["magic", "NUMPX"],
    );
    expect_err(
        read(b"\x93NUMPY\x04\x00\x10\x00", Format::Npy),
        "malformed",
        &["version 4.0"],
    );
    expect_err(
        read(b"\x93NUMPY\x01\x00\xff\x00{", Format::Npy),
        "truncated",
        &["265", "11"],
    );
    let mut no_shape = NPY_MAGIC.to_vec();
    let header = "{'descr': '<f4', 'fortran_order': False}";
    no_shape.extend_from_slice(&[1, 0, header.len() as u8, 0]);
    no_shape.extend_from_slice(header.as_bytes());
    expect_err(
        read(&no_shape, Format::Npy),
        "malformed",
        &["no 'shape' key"],
    );
    let mut garbage = NPY_MAGIC.to_vec();
    garbage.extend_from_slice(&[1, 0, 12, 0]);
    garbage.extend_from_slice(b"{'descr': @}");
    expect_err(
        read(&garbage, Format::Npy),
        "malformed",
        &["header dict", "'@'"],
    );
}

#[test]
fn json_shapes_and_errors() {
    let bare = read(b"[[1, 2, 3], [4.5, -5, 6e-3]]", Format::Json).unwrap();
    assert_eq!(bare.points, vec![[1.0, 2.0, 3.0], [4.5, -5.0, 6e-3]]);
    let obj = read(br#"{"units": "m", "points": [[1, 2, 3]]}"#, Format::Json).unwrap();
    assert_eq!(obj.points, vec![[1.0, 2.0, 3.0]]);
    let mut twelve = vec!["[0,0,0]"; 12];
    twelve.push("[1,2]");
    let text = format!("{{\"points\": [{}]}}", twelve.join(","));
    expect_err(
        read(text.as_bytes(), Format::Json),
        "malformed",
        &["points[12] has 2 values, expected 3"],
    );
    expect_err(
        read(br#""hello""#, Format::Json),
        "malformed",
        &["top-level value is a string", "hello"],
    );
    expect_err(
        read(b"[1, 2, 3]", Format::Json),
        "malformed",
        &["points[0] is a number (1)", "flat"],
    );
    expect_err(
        read(br#"{"pts": []}"#, Format::Json),
        "malformed",
        &["no 'points' key", "pts"],
    );
    expect_err(
        read(br#"{"points": 3}"#, Format::Json),
        "malformed",
        &["'points' is a number (3)"],
    );
    expect_err(
        read(br#"[[1, "2", 3]]"#, Format::Json),
        "malformed",
        &["points[0][1] is a string"],
    );
    expect_err(
        read(b"[[1, 2, 3]", Format::Json),
        "malformed",
        &["not valid JSON", "line 1"],
    );
    let deep = "[".repeat(100_000);
    expect_err(
        read(deep.as_bytes(), Format::Json),
        "malformed",
        &["not valid JSON"],
    );
}

#[test]
fn json_written_compact_and_short() {
    let c = PointCloud {
        points: vec![[0.1, -2.0, 1e-7]],
    };
    assert_eq!(
        String::from_utf8(c.to_bytes(Format::Json)).unwrap(),
        r#"{"points":[[0.1,-2.0,1e-7]]}"#
    );
}

#[test]
fn bounds_and_error_types() {
    assert_eq!(PointCloud::default().bounds(), None);
    let c = PointCloud {
        points: vec![[1.0, -1.0, 5.0], [-2.0, 3.0, 4.0], [0.0, 0.0, 6.0]],
    };
    assert_eq!(c.bounds(), Some(([-2.0, -1.0, 4.0], [1.0, 3.0, 6.0])));
    let io = PointCloudError::Io {
        path: "p".into(),
        source: std::io::Error::other("x"),
    };
    let kinds: Vec<&str> = [
        io,
        PointCloudError::UnknownFormat { path: "p".into() },
        mal(PLY, "d"),
        truncated(NPY, 2, 1),
        PointCloudError::NonFinite {
            index: 0,
            axis: 0,
            value: f32::NAN,
        },
        PointCloudError::Empty,
        PointCloudError::TooFew { count: 1, min: 2 },
        PointCloudError::TooMany { count: 2, max: 1 },
    ]
    .iter()
    .map(PointCloudError::error_type)
    .collect();
    assert_eq!(
        kinds,
        [
            "io",
            "unknown_format",
            "malformed",
            "truncated",
            "non_finite",
            "empty",
            "too_few",
            "too_many"
        ]
    );
}

#[test]
fn coloured_ply_is_readable_and_checks_lengths() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.ply");
    let pts = [[0.5f32, 1.0, -1.0], [2.0, 3.0, 4.0]];
    write_coloured_ply(&path, &pts, &[[255, 0, 0], [0, 128, 255]]).unwrap();
    let text = fs::read_to_string(&path).unwrap();
    assert!(text.contains("property uchar red\n"), "{text}");
    assert!(text.ends_with("2.0 3.0 4.0 0 128 255\n"), "{text}");
    assert_eq!(
        PointCloud::read(&path, &Limits::default()).unwrap().points,
        pts
    );
    let err = write_coloured_ply(&path, &pts, &[[0, 0, 0]]).unwrap_err();
    assert_eq!(err.error_type(), "malformed");
    assert!(err.to_string().contains("2 points but 1 colours"), "{err}");
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
}

// ---- property tests ----------------------------------------------------------------

fn finite_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        -10.0f32..10.0,
        prop::num::f32::NORMAL | prop::num::f32::SUBNORMAL | prop::num::f32::ZERO,
    ]
}

fn cloud_strategy(max: usize) -> impl Strategy<Value = PointCloud> {
    prop::collection::vec([finite_f32(), finite_f32(), finite_f32()], 1..max)
        .prop_map(|points| PointCloud { points })
}

fn small_limits() -> Limits {
    Limits {
        min_points: 1,
        max_points: 4096,
    }
}

/// Every reader, every format: must return, never panic.
fn feed_all(bytes: &[u8]) {
    for format in ALL {
        let _ = PointCloud::from_bytes(bytes, format, &small_limits());
        let _ = PointCloud::from_bytes(
            bytes,
            format,
            &Limits {
                min_points: 0,
                max_points: usize::MAX,
            },
        );
    }
}

fn header_strategy() -> impl Strategy<Value = Vec<u8>> {
    let count = prop_oneof![
        0u64..8,
        Just(1_000_000_000_000u64),
        Just(u64::MAX),
        any::<u64>()
    ];
    let ply = (
        prop::sample::select(vec!["ascii", "binary_little_endian", "binary_big_endian"]),
        prop::sample::select(vec![
            XYZ_FLOAT,
            "property double z\nproperty uchar q\nproperty int x\nproperty float y\n",
            "property float x\nproperty float y\nproperty float z\nproperty list uchar int l\n",
        ]),
        count.clone(),
        any::<bool>(),
    )
        .prop_map(|(enc, props, n, face)| {
            let mut h = format!("ply\nformat {enc} 1.0\nelement vertex {n}\n{props}");
            if face {
                h.push_str("element face 3\nproperty list uchar int vertex_indices\n");
            }
            h.push_str("end_header\n");
            h.into_bytes()
        });
    let npy_header = (
        prop::sample::select(vec!["<f4", ">f4", "<f8", ">f8"]),
        any::<bool>(),
        count,
    )
        .prop_map(|(d, f, n)| npy(d, f, &format!("({n}, 3)"), &[]));
    prop_oneof![ply, npy_header, Just(b"{\"points\": [[".to_vec())]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn prop_round_trip_all_formats(cloud in cloud_strategy(64)) {
        for format in ALL {
            let back = PointCloud::from_bytes(&cloud.to_bytes(format), format, &Limits::default());
            let back = back.map_err(|e| TestCaseError::fail(format!("{format:?}: {e}")))?;
            prop_assert_eq!(bits(&back.points), bits(&cloud.points), "{:?}", format);
        }
    }

    #[test]
    fn prop_arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..512)) {
        feed_all(&bytes);
        // The same bytes behind each format's magic, so they get past the first check.
        for prefix in [&b"ply\n"[..], b"ply\nformat ascii 1.0\n", b"\x93NUMPY\x01\x00"] {
            let mut v = prefix.to_vec();
            v.extend_from_slice(&bytes);
            feed_all(&v);
        }
    }

    #[test]
    fn prop_valid_header_then_garbage_never_panics(
        header in header_strategy(),
        tail in prop::collection::vec(any::<u8>(), 0..256),
    ) {
        let mut bytes = header;
        bytes.extend_from_slice(&tail);
        feed_all(&bytes);
    }

    #[test]
    fn prop_mutated_valid_files_never_panic(
        cloud in cloud_strategy(16),
        format in prop::sample::select(ALL.to_vec()),
        cut in any::<prop::sample::Index>(),
        flips in prop::collection::vec((any::<prop::sample::Index>(), 1u8..=255), 0..6),
    ) {
        let bytes = cloud.to_bytes(format);
        let mut flipped = bytes.clone();
        for (at, xor) in &flips {
            let i = at.index(flipped.len());
            flipped[i] ^= xor;
        }
        feed_all(&flipped);
        let truncated = &bytes[..cut.index(bytes.len() + 1)];
        feed_all(truncated);
        if truncated.len() < bytes.len() && format != Format::PlyAscii && format != Format::Json {
            // Binary formats: any truncation is an error, never a silently shorter cloud.
            prop_assert!(PointCloud::from_bytes(truncated, format, &Limits::default()).is_err());
        }
    }
}
