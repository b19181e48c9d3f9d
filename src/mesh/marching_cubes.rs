//! Marching-cubes iso-surface extraction from a dense grid of signed-distance samples.
//!
//! Why: part shapes are signed distance fields, and exporting, rendering or measuring them needs
//! an explicit triangle mesh. This module turns a sampled SDF into an indexed triangle mesh with
//! nothing but `std`.
//!
//! Algorithm: classic marching cubes (Lorensen & Cline, SIGGRAPH 1987). Every cell of the grid is
//! classified by which of its 8 corners are inside (`value < level`), giving one of 256 cases; the
//! case selects the crossed cell edges (edge table) and how the edge vertices are joined into
//! triangles (triangle table). Vertices are linearly interpolated along the cell edges and shared
//! between neighbouring cells through an edge-indexed cache, so a closed surface yields a
//! watertight, edge-manifold mesh. The cache keeps per-slab arrays (x and y edges of the two
//! sample planes bounding the current slab of cells, z edges between them) instead of a hash map;
//! a vertex that lands exactly on a grid corner is welded to that corner (a small hash map, rarely
//! used) so that coincident vertices share one index and zero-area triangles can be dropped
//! without opening the surface.
//!
//! Tables: the standard 256-entry edge table and triangle table from Paul Bourke's public-domain
//! "Polygonising a scalar field" (1994, based on tables by Cory Gene Bloyd); the data below was
//! copied verbatim and is checked by the tests (edge table re-derived from its definition,
//! triangle table consistent with it, complementary cases using the same edges).
//!
//! Cube numbering (as in Bourke): corners 0..8 are (0,0,0), (1,0,0), (1,1,0), (0,1,0), (0,0,1),
//! (1,0,1), (1,1,1), (0,1,1) in (x, y, z) cell offsets; edges 0..4 join corners 0-1, 1-2, 2-3,
//! 3-0, edges 4..8 join 4-5, 5-6, 6-7, 7-4, and edges 8..12 join 0-4, 1-5, 2-6, 3-7.
//!
//! Orientation: the field is negative inside. Output triangles are counter-clockwise when seen
//! from outside (where the field is > level), so the right-hand-rule normals point outwards. With
//! the corner bit set for inside corners, Bourke's table lists triangles the other way round, so
//! each table triangle `(a, b, c)` is emitted as `(a, c, b)`.

use std::collections::HashMap;

/// A dense grid of SDF samples at the points origin + spacing * (i, j, k).
pub struct ScalarGrid<'a> {
    /// Number of sample points per axis (x, y, z); each >= 2.
    pub dims: [usize; 3],
    /// Position of sample (0, 0, 0).
    pub origin: [f32; 3],
    /// Distance between neighbouring samples per axis (> 0).
    pub spacing: [f32; 3],
    /// Samples, x fastest: index = i + dims[0] * (j + dims[1] * k). len == dims product.
    pub values: &'a [f32],
}

const AXIS_NAMES: [&str; 3] = ["x", "y", "z"];

impl ScalarGrid<'_> {
    /// Checks the grid description: every `dims` entry >= 2, every `spacing` entry finite and
    /// positive, every `origin` entry finite, and `values.len()` equal to the product of `dims`.
    /// The error message names the offending field, the limit and the value found.
    pub fn validate(&self) -> Result<(), String> {
        for (axis, name) in AXIS_NAMES.iter().enumerate() {
            let n = self.dims[axis];
            if n < 2 {
                return Err(format!(
                    "ScalarGrid.dims[{axis}] ({name}) must be >= 2, got {n}"
                ));
            }
            let h = self.spacing[axis];
            if !(h.is_finite() && h > 0.0) {
                return Err(format!(
                    "ScalarGrid.spacing[{axis}] ({name}) must be finite and > 0, got {h}"
                ));
            }
            let o = self.origin[axis];
            if !o.is_finite() {
                return Err(format!(
                    "ScalarGrid.origin[{axis}] ({name}) must be finite, got {o}"
                ));
            }
        }
        let [nx, ny, nz] = self.dims;
        let expected = nx
            .checked_mul(ny)
            .and_then(|p| p.checked_mul(nz))
            .ok_or_else(|| {
                format!("ScalarGrid.dims product overflows usize: dims = [{nx}, {ny}, {nz}]")
            })?;
        if self.values.len() != expected {
            return Err(format!(
                "ScalarGrid.values.len() must equal dims[0] * dims[1] * dims[2] = \
                 {nx} * {ny} * {nz} = {expected}, got {}",
                self.values.len()
            ));
        }
        Ok(())
    }
}

/// Indexed triangle mesh produced by extraction.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct McMesh {
    /// Vertex positions, in the grid's coordinate frame; every vertex is used by a triangle.
    pub positions: Vec<[f32; 3]>,
    /// Counter-clockwise when seen from OUTSIDE (where the field is > level), i.e. normals point outwards.
    pub triangles: Vec<[u32; 3]>,
}

/// Extract the iso-surface `value == level`. Vertices on grid edges are shared between neighbouring
/// cells (an edge-indexed cache), so a closed surface that does not touch the grid boundary gives a
/// watertight, edge-manifold mesh. Triangles of zero area (two or three coincident vertices) are dropped.
/// Non-finite samples are treated as "outside" (+infinity-like, i.e. > level) so they never panic.
///
/// A sample is inside when it is finite and `< level`. Every returned vertex is used by at least
/// one triangle. Errors: an invalid grid (see [`ScalarGrid::validate`]), a non-finite `level`, or
/// more vertices than a `u32` index can address.
pub fn marching_cubes(grid: &ScalarGrid<'_>, level: f32) -> Result<McMesh, String> {
    grid.validate()?;
    if !level.is_finite() {
        return Err(format!("marching_cubes: level must be finite, got {level}"));
    }
    let mut ex = Extractor::new(grid, level);
    ex.run()?;
    Ok(ex.finish())
}

/// Marks an empty slot of the edge-vertex cache.
const NONE: u32 = u32::MAX;

/// For each cube edge: offset (di, dj, dk) of its lower corner from the cell's corner 0, and the
/// axis it runs along.
const EDGE_GEOMETRY: [([usize; 3], usize); 12] = [
    ([0, 0, 0], 0),
    ([1, 0, 0], 1),
    ([0, 1, 0], 0),
    ([0, 0, 0], 1),
    ([0, 0, 1], 0),
    ([1, 0, 1], 1),
    ([0, 1, 1], 0),
    ([0, 0, 1], 1),
    ([0, 0, 0], 2),
    ([1, 0, 0], 2),
    ([1, 1, 0], 2),
    ([0, 1, 0], 2),
];

/// The cell corners in Bourke's order as (di, dj, dk) offsets.
const CORNER_OFFSETS: [[usize; 3]; 8] = [
    [0, 0, 0],
    [1, 0, 0],
    [1, 1, 0],
    [0, 1, 0],
    [0, 0, 1],
    [1, 0, 1],
    [1, 1, 1],
    [0, 1, 1],
];

/// Edge-vertex cache for one slab of cells (between sample planes k and k + 1). Each array is
/// indexed by the lower corner's in-plane index `i + nx * j`.
struct SlabCache {
    /// x edges of plane k and of plane k + 1.
    x: [Vec<u32>; 2],
    /// y edges of plane k and of plane k + 1.
    y: [Vec<u32>; 2],
    /// z edges between plane k and plane k + 1.
    z: Vec<u32>,
}

impl SlabCache {
    fn new(plane: usize) -> Self {
        Self {
            x: [vec![NONE; plane], vec![NONE; plane]],
            y: [vec![NONE; plane], vec![NONE; plane]],
            z: vec![NONE; plane],
        }
    }

    /// Moves on to the next slab: the upper plane becomes the lower one.
    fn advance(&mut self) {
        self.x.swap(0, 1);
        self.y.swap(0, 1);
        self.x[1].fill(NONE);
        self.y[1].fill(NONE);
        self.z.fill(NONE);
    }

    fn slot(&mut self, axis: usize, upper: usize, plane_index: usize) -> &mut u32 {
        match axis {
            0 => &mut self.x[upper][plane_index],
            1 => &mut self.y[upper][plane_index],
            _ => &mut self.z[plane_index],
        }
    }
}

struct Extractor<'g, 'a> {
    grid: &'g ScalarGrid<'a>,
    level: f32,
    /// Sample coordinates per axis: coords[a][i] = origin[a] + spacing[a] * i.
    coords: [Vec<f32>; 3],
    /// Vertices welded to grid corners, keyed by the corner's linear sample index.
    corner_vertices: HashMap<usize, u32>,
    positions: Vec<[f32; 3]>,
    triangles: Vec<[u32; 3]>,
}

impl<'g, 'a> Extractor<'g, 'a> {
    fn new(grid: &'g ScalarGrid<'a>, level: f32) -> Self {
        let coords = std::array::from_fn(|a| {
            (0..grid.dims[a])
                .map(|i| grid.origin[a] + grid.spacing[a] * i as f32)
                .collect()
        });
        Self {
            grid,
            level,
            coords,
            corner_vertices: HashMap::new(),
            positions: Vec::new(),
            triangles: Vec::new(),
        }
    }

    /// Whether a sample counts as inside: finite and below the level.
    #[inline]
    fn inside(&self, v: f32) -> bool {
        v < self.level && v > f32::NEG_INFINITY
    }

    fn run(&mut self) -> Result<(), String> {
        let [nx, ny, nz] = self.grid.dims;
        let plane = nx * ny;
        let values = self.grid.values;
        // Linear-index offsets of the 8 cell corners from corner 0.
        let corner_step: [usize; 8] = CORNER_OFFSETS.map(|[di, dj, dk]| di + nx * dj + plane * dk);
        let mut cache = SlabCache::new(plane);
        for k in 0..nz - 1 {
            if k > 0 {
                cache.advance();
            }
            for j in 0..ny - 1 {
                let row = nx * (j + ny * k);
                // Inside flags of the cell's corners 1, 2, 5, 6 become 0, 3, 4, 7 of the next cell.
                let mut prev = [
                    self.inside(values[row]),
                    self.inside(values[row + nx]),
                    self.inside(values[row + plane]),
                    self.inside(values[row + nx + plane]),
                ];
                for i in 0..nx - 1 {
                    let base = row + i;
                    let next = [
                        self.inside(values[base + corner_step[1]]),
                        self.inside(values[base + corner_step[2]]),
                        self.inside(values[base + corner_step[5]]),
                        self.inside(values[base + corner_step[6]]),
                    ];
                    let case = usize::from(prev[0])
                        | usize::from(next[0]) << 1
                        | usize::from(next[1]) << 2
                        | usize::from(prev[1]) << 3
                        | usize::from(prev[2]) << 4
                        | usize::from(next[2]) << 5
                        | usize::from(next[3]) << 6
                        | usize::from(prev[3]) << 7;
                    prev = next;
                    if case == 0 || case == 255 {
                        continue;
                    }
                    self.polygonise_cell([i, j, k], case, &mut cache)?;
                }
            }
        }
        Ok(())
    }

    fn polygonise_cell(
        &mut self,
        cell: [usize; 3],
        case: usize,
        cache: &mut SlabCache,
    ) -> Result<(), String> {
        let nx = self.grid.dims[0];
        let edges = EDGE_TABLE[case];
        let mut vid = [NONE; 12];
        for (e, (slot_out, &(offset, axis))) in vid.iter_mut().zip(EDGE_GEOMETRY.iter()).enumerate()
        {
            if edges & (1 << e) == 0 {
                continue;
            }
            let lower = [
                cell[0] + offset[0],
                cell[1] + offset[1],
                cell[2] + offset[2],
            ];
            let slot = cache.slot(axis, offset[2], lower[0] + nx * lower[1]);
            if *slot == NONE {
                *slot = self.edge_vertex(lower, axis)?;
            }
            *slot_out = *slot;
        }
        for tri in TRI_TABLE[case].chunks_exact(3) {
            if tri[0] < 0 {
                break;
            }
            // Table entries are 0..12 here; the table test checks this for all cases.
            let [a, b, c] = [0, 1, 2].map(|m| vid[tri[m] as usize]);
            // Reversed to make the winding counter-clockwise seen from outside.
            self.push_triangle([a, c, b]);
        }
        Ok(())
    }

    /// Creates the vertex where the surface crosses the grid edge from sample `lower` one step
    /// along `axis`. Depends only on the edge, so it is the same whichever cell asks for it.
    fn edge_vertex(&mut self, lower: [usize; 3], axis: usize) -> Result<u32, String> {
        let [nx, ny, _] = self.grid.dims;
        let stride = [1, nx, nx * ny][axis];
        let c0 = lower[0] + nx * (lower[1] + ny * lower[2]);
        let c1 = c0 + stride;
        let v0 = self.grid.values[c0];
        let v1 = self.grid.values[c1];
        // Non-finite samples behave like +infinity: the crossing sits at the finite end.
        let t = if !v0.is_finite() {
            1.0
        } else if !v1.is_finite() {
            0.0
        } else if v1 == v0 {
            0.5
        } else {
            // In f64 so that neither difference can overflow.
            ((f64::from(self.level) - f64::from(v0)) / (f64::from(v1) - f64::from(v0)))
                .clamp(0.0, 1.0)
        };
        let a = self.coords[axis][lower[axis]];
        let b = self.coords[axis][lower[axis] + 1];
        let along = (f64::from(a) + t * (f64::from(b) - f64::from(a))) as f32;
        let along = along.clamp(a, b);
        let mut p = [
            self.coords[0][lower[0]],
            self.coords[1][lower[1]],
            self.coords[2][lower[2]],
        ];
        p[axis] = along;
        let corner = if along == a {
            Some(c0)
        } else if along == b {
            Some(c1)
        } else {
            None
        };
        match corner {
            None => self.push_vertex(p),
            Some(c) => {
                if let Some(&id) = self.corner_vertices.get(&c) {
                    return Ok(id);
                }
                let id = self.push_vertex(p)?;
                self.corner_vertices.insert(c, id);
                Ok(id)
            }
        }
    }

    fn push_vertex(&mut self, p: [f32; 3]) -> Result<u32, String> {
        let id = u32::try_from(self.positions.len())
            .ok()
            .filter(|&id| id != NONE)
            .ok_or_else(|| {
                format!(
                    "marching_cubes: more than {} vertices do not fit u32 indices",
                    NONE - 1
                )
            })?;
        self.positions.push(p);
        Ok(id)
    }

    /// Keeps the triangle unless it has zero area (coincident or exactly collinear vertices).
    fn push_triangle(&mut self, t: [u32; 3]) {
        if t[0] == t[1] || t[1] == t[2] || t[2] == t[0] {
            return;
        }
        let [p, q, r] = t.map(|i| self.positions[i as usize].map(f64::from));
        let u = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
        let v = [r[0] - p[0], r[1] - p[1], r[2] - p[2]];
        let n = [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ];
        if n == [0.0; 3] {
            return;
        }
        self.triangles.push(t);
    }

    /// Drops vertices no kept triangle uses (possible only when triangles were dropped) and
    /// returns the mesh.
    fn finish(self) -> McMesh {
        let Self {
            mut positions,
            mut triangles,
            ..
        } = self;
        let mut remap = vec![NONE; positions.len()];
        for t in &triangles {
            for &i in t {
                remap[i as usize] = 0;
            }
        }
        if remap.contains(&NONE) {
            let mut kept = 0u32;
            let mut write = 0usize;
            for read in 0..positions.len() {
                if remap[read] != NONE {
                    remap[read] = kept;
                    positions[write] = positions[read];
                    write += 1;
                    kept += 1;
                }
            }
            positions.truncate(write);
            for t in &mut triangles {
                *t = t.map(|i| remap[i as usize]);
            }
        }
        McMesh {
            positions,
            triangles,
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Tables (Paul Bourke, "Polygonising a scalar field", public domain). They sit at the bottom of
// the implementation, just above the tests (clippy rejects items after the test module).
// ---------------------------------------------------------------------------------------------

/// Bit `e` of `EDGE_TABLE[case]` is set when cube edge `e` crosses the surface in that case.
#[rustfmt::skip]
const EDGE_TABLE: [u16; 256] = [
    0x000, 0x109, 0x203, 0x30a, 0x406, 0x50f, 0x605, 0x70c,
    0x80c, 0x905, 0xa0f, 0xb06, 0xc0a, 0xd03, 0xe09, 0xf00,
    0x190, 0x099, 0x393, 0x29a, 0x596, 0x49f, 0x795, 0x69c,
    0x99c, 0x895, 0xb9f, 0xa96, 0xd9a, 0xc93, 0xf99, 0xe90,
    0x230, 0x339, 0x033, 0x13a, 0x636, 0x73f, 0x435, 0x53c,
    0xa3c, 0xb35, 0x83f, 0x936, 0xe3a, 0xf33, 0xc39, 0xd30,
    0x3a0, 0x2a9, 0x1a3, 0x0aa, 0x7a6, 0x6af, 0x5a5, 0x4ac,
    0xbac, 0xaa5, 0x9af, 0x8a6, 0xfaa, 0xea3, 0xda9, 0xca0,
    0x460, 0x569, 0x663, 0x76a, 0x066, 0x16f, 0x265, 0x36c,
    0xc6c, 0xd65, 0xe6f, 0xf66, 0x86a, 0x963, 0xa69, 0xb60,
    0x5f0, 0x4f9, 0x7f3, 0x6fa, 0x1f6, 0x0ff, 0x3f5, 0x2fc,
    0xdfc, 0xcf5, 0xfff, 0xef6, 0x9fa, 0x8f3, 0xbf9, 0xaf0,
    0x650, 0x759, 0x453, 0x55a, 0x256, 0x35f, 0x055, 0x15c,
    0xe5c, 0xf55, 0xc5f, 0xd56, 0xa5a, 0xb53, 0x859, 0x950,
    0x7c0, 0x6c9, 0x5c3, 0x4ca, 0x3c6, 0x2cf, 0x1c5, 0x0cc,
    0xfcc, 0xec5, 0xdcf, 0xcc6, 0xbca, 0xac3, 0x9c9, 0x8c0,
    0x8c0, 0x9c9, 0xac3, 0xbca, 0xcc6, 0xdcf, 0xec5, 0xfcc,
    0x0cc, 0x1c5, 0x2cf, 0x3c6, 0x4ca, 0x5c3, 0x6c9, 0x7c0,
    0x950, 0x859, 0xb53, 0xa5a, 0xd56, 0xc5f, 0xf55, 0xe5c,
    0x15c, 0x055, 0x35f, 0x256, 0x55a, 0x453, 0x759, 0x650,
    0xaf0, 0xbf9, 0x8f3, 0x9fa, 0xef6, 0xfff, 0xcf5, 0xdfc,
    0x2fc, 0x3f5, 0x0ff, 0x1f6, 0x6fa, 0x7f3, 0x4f9, 0x5f0,
    0xb60, 0xa69, 0x963, 0x86a, 0xf66, 0xe6f, 0xd65, 0xc6c,
    0x36c, 0x265, 0x16f, 0x066, 0x76a, 0x663, 0x569, 0x460,
    0xca0, 0xda9, 0xea3, 0xfaa, 0x8a6, 0x9af, 0xaa5, 0xbac,
    0x4ac, 0x5a5, 0x6af, 0x7a6, 0x0aa, 0x1a3, 0x2a9, 0x3a0,
    0xd30, 0xc39, 0xf33, 0xe3a, 0x936, 0x83f, 0xb35, 0xa3c,
    0x53c, 0x435, 0x73f, 0x636, 0x13a, 0x033, 0x339, 0x230,
    0xe90, 0xf99, 0xc93, 0xd9a, 0xa96, 0xb9f, 0x895, 0x99c,
    0x69c, 0x795, 0x49f, 0x596, 0x29a, 0x393, 0x099, 0x190,
    0xf00, 0xe09, 0xd03, 0xc0a, 0xb06, 0xa0f, 0x905, 0x80c,
    0x70c, 0x605, 0x50f, 0x406, 0x30a, 0x203, 0x109, 0x000,
];

/// Triangles (as triples of cube edge indices) for each case, terminated by -1.
#[rustfmt::skip]
const TRI_TABLE: [[i8; 16]; 256] = [
    [-1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 3, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 1, 9, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 8, 3, 9, 8, 1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 10, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 3, 1, 2, 10, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [9, 2, 10, 0, 2, 9, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [2, 8, 3, 2, 10, 8, 10, 9, 8, -1, -1, -1, -1, -1, -1, -1],
    [3, 11, 2, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 11, 2, 8, 11, 0, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 9, 0, 2, 3, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 11, 2, 1, 9, 11, 9, 8, 11, -1, -1, -1, -1, -1, -1, -1],
    [3, 10, 1, 11, 10, 3, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 10, 1, 0, 8, 10, 8, 11, 10, -1, -1, -1, -1, -1, -1, -1],
    [3, 9, 0, 3, 11, 9, 11, 10, 9, -1, -1, -1, -1, -1, -1, -1],
    [9, 8, 10, 10, 8, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 7, 8, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 3, 0, 7, 3, 4, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 1, 9, 8, 4, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 1, 9, 4, 7, 1, 7, 3, 1, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 10, 8, 4, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [3, 4, 7, 3, 0, 4, 1, 2, 10, -1, -1, -1, -1, -1, -1, -1],
    [9, 2, 10, 9, 0, 2, 8, 4, 7, -1, -1, -1, -1, -1, -1, -1],
    [2, 10, 9, 2, 9, 7, 2, 7, 3, 7, 9, 4, -1, -1, -1, -1],
    [8, 4, 7, 3, 11, 2, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [11, 4, 7, 11, 2, 4, 2, 0, 4, -1, -1, -1, -1, -1, -1, -1],
    [9, 0, 1, 8, 4, 7, 2, 3, 11, -1, -1, -1, -1, -1, -1, -1],
    [4, 7, 11, 9, 4, 11, 9, 11, 2, 9, 2, 1, -1, -1, -1, -1],
    [3, 10, 1, 3, 11, 10, 7, 8, 4, -1, -1, -1, -1, -1, -1, -1],
    [1, 11, 10, 1, 4, 11, 1, 0, 4, 7, 11, 4, -1, -1, -1, -1],
    [4, 7, 8, 9, 0, 11, 9, 11, 10, 11, 0, 3, -1, -1, -1, -1],
    [4, 7, 11, 4, 11, 9, 9, 11, 10, -1, -1, -1, -1, -1, -1, -1],
    [9, 5, 4, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [9, 5, 4, 0, 8, 3, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 5, 4, 1, 5, 0, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [8, 5, 4, 8, 3, 5, 3, 1, 5, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 10, 9, 5, 4, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [3, 0, 8, 1, 2, 10, 4, 9, 5, -1, -1, -1, -1, -1, -1, -1],
    [5, 2, 10, 5, 4, 2, 4, 0, 2, -1, -1, -1, -1, -1, -1, -1],
    [2, 10, 5, 3, 2, 5, 3, 5, 4, 3, 4, 8, -1, -1, -1, -1],
    [9, 5, 4, 2, 3, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 11, 2, 0, 8, 11, 4, 9, 5, -1, -1, -1, -1, -1, -1, -1],
    [0, 5, 4, 0, 1, 5, 2, 3, 11, -1, -1, -1, -1, -1, -1, -1],
    [2, 1, 5, 2, 5, 8, 2, 8, 11, 4, 8, 5, -1, -1, -1, -1],
    [10, 3, 11, 10, 1, 3, 9, 5, 4, -1, -1, -1, -1, -1, -1, -1],
    [4, 9, 5, 0, 8, 1, 8, 10, 1, 8, 11, 10, -1, -1, -1, -1],
    [5, 4, 0, 5, 0, 11, 5, 11, 10, 11, 0, 3, -1, -1, -1, -1],
    [5, 4, 8, 5, 8, 10, 10, 8, 11, -1, -1, -1, -1, -1, -1, -1],
    [9, 7, 8, 5, 7, 9, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [9, 3, 0, 9, 5, 3, 5, 7, 3, -1, -1, -1, -1, -1, -1, -1],
    [0, 7, 8, 0, 1, 7, 1, 5, 7, -1, -1, -1, -1, -1, -1, -1],
    [1, 5, 3, 3, 5, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [9, 7, 8, 9, 5, 7, 10, 1, 2, -1, -1, -1, -1, -1, -1, -1],
    [10, 1, 2, 9, 5, 0, 5, 3, 0, 5, 7, 3, -1, -1, -1, -1],
    [8, 0, 2, 8, 2, 5, 8, 5, 7, 10, 5, 2, -1, -1, -1, -1],
    [2, 10, 5, 2, 5, 3, 3, 5, 7, -1, -1, -1, -1, -1, -1, -1],
    [7, 9, 5, 7, 8, 9, 3, 11, 2, -1, -1, -1, -1, -1, -1, -1],
    [9, 5, 7, 9, 7, 2, 9, 2, 0, 2, 7, 11, -1, -1, -1, -1],
    [2, 3, 11, 0, 1, 8, 1, 7, 8, 1, 5, 7, -1, -1, -1, -1],
    [11, 2, 1, 11, 1, 7, 7, 1, 5, -1, -1, -1, -1, -1, -1, -1],
    [9, 5, 8, 8, 5, 7, 10, 1, 3, 10, 3, 11, -1, -1, -1, -1],
    [5, 7, 0, 5, 0, 9, 7, 11, 0, 1, 0, 10, 11, 10, 0, -1],
    [11, 10, 0, 11, 0, 3, 10, 5, 0, 8, 0, 7, 5, 7, 0, -1],
    [11, 10, 5, 7, 11, 5, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [10, 6, 5, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 3, 5, 10, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [9, 0, 1, 5, 10, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 8, 3, 1, 9, 8, 5, 10, 6, -1, -1, -1, -1, -1, -1, -1],
    [1, 6, 5, 2, 6, 1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 6, 5, 1, 2, 6, 3, 0, 8, -1, -1, -1, -1, -1, -1, -1],
    [9, 6, 5, 9, 0, 6, 0, 2, 6, -1, -1, -1, -1, -1, -1, -1],
    [5, 9, 8, 5, 8, 2, 5, 2, 6, 3, 2, 8, -1, -1, -1, -1],
    [2, 3, 11, 10, 6, 5, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [11, 0, 8, 11, 2, 0, 10, 6, 5, -1, -1, -1, -1, -1, -1, -1],
    [0, 1, 9, 2, 3, 11, 5, 10, 6, -1, -1, -1, -1, -1, -1, -1],
    [5, 10, 6, 1, 9, 2, 9, 11, 2, 9, 8, 11, -1, -1, -1, -1],
    [6, 3, 11, 6, 5, 3, 5, 1, 3, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 11, 0, 11, 5, 0, 5, 1, 5, 11, 6, -1, -1, -1, -1],
    [3, 11, 6, 0, 3, 6, 0, 6, 5, 0, 5, 9, -1, -1, -1, -1],
    [6, 5, 9, 6, 9, 11, 11, 9, 8, -1, -1, -1, -1, -1, -1, -1],
    [5, 10, 6, 4, 7, 8, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 3, 0, 4, 7, 3, 6, 5, 10, -1, -1, -1, -1, -1, -1, -1],
    [1, 9, 0, 5, 10, 6, 8, 4, 7, -1, -1, -1, -1, -1, -1, -1],
    [10, 6, 5, 1, 9, 7, 1, 7, 3, 7, 9, 4, -1, -1, -1, -1],
    [6, 1, 2, 6, 5, 1, 4, 7, 8, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 5, 5, 2, 6, 3, 0, 4, 3, 4, 7, -1, -1, -1, -1],
    [8, 4, 7, 9, 0, 5, 0, 6, 5, 0, 2, 6, -1, -1, -1, -1],
    [7, 3, 9, 7, 9, 4, 3, 2, 9, 5, 9, 6, 2, 6, 9, -1],
    [3, 11, 2, 7, 8, 4, 10, 6, 5, -1, -1, -1, -1, -1, -1, -1],
    [5, 10, 6, 4, 7, 2, 4, 2, 0, 2, 7, 11, -1, -1, -1, -1],
    [0, 1, 9, 4, 7, 8, 2, 3, 11, 5, 10, 6, -1, -1, -1, -1],
    [9, 2, 1, 9, 11, 2, 9, 4, 11, 7, 11, 4, 5, 10, 6, -1],
    [8, 4, 7, 3, 11, 5, 3, 5, 1, 5, 11, 6, -1, -1, -1, -1],
    [5, 1, 11, 5, 11, 6, 1, 0, 11, 7, 11, 4, 0, 4, 11, -1],
    [0, 5, 9, 0, 6, 5, 0, 3, 6, 11, 6, 3, 8, 4, 7, -1],
    [6, 5, 9, 6, 9, 11, 4, 7, 9, 7, 11, 9, -1, -1, -1, -1],
    [10, 4, 9, 6, 4, 10, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 10, 6, 4, 9, 10, 0, 8, 3, -1, -1, -1, -1, -1, -1, -1],
    [10, 0, 1, 10, 6, 0, 6, 4, 0, -1, -1, -1, -1, -1, -1, -1],
    [8, 3, 1, 8, 1, 6, 8, 6, 4, 6, 1, 10, -1, -1, -1, -1],
    [1, 4, 9, 1, 2, 4, 2, 6, 4, -1, -1, -1, -1, -1, -1, -1],
    [3, 0, 8, 1, 2, 9, 2, 4, 9, 2, 6, 4, -1, -1, -1, -1],
    [0, 2, 4, 4, 2, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [8, 3, 2, 8, 2, 4, 4, 2, 6, -1, -1, -1, -1, -1, -1, -1],
    [10, 4, 9, 10, 6, 4, 11, 2, 3, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 2, 2, 8, 11, 4, 9, 10, 4, 10, 6, -1, -1, -1, -1],
    [3, 11, 2, 0, 1, 6, 0, 6, 4, 6, 1, 10, -1, -1, -1, -1],
    [6, 4, 1, 6, 1, 10, 4, 8, 1, 2, 1, 11, 8, 11, 1, -1],
    [9, 6, 4, 9, 3, 6, 9, 1, 3, 11, 6, 3, -1, -1, -1, -1],
    [8, 11, 1, 8, 1, 0, 11, 6, 1, 9, 1, 4, 6, 4, 1, -1],
    [3, 11, 6, 3, 6, 0, 0, 6, 4, -1, -1, -1, -1, -1, -1, -1],
    [6, 4, 8, 11, 6, 8, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [7, 10, 6, 7, 8, 10, 8, 9, 10, -1, -1, -1, -1, -1, -1, -1],
    [0, 7, 3, 0, 10, 7, 0, 9, 10, 6, 7, 10, -1, -1, -1, -1],
    [10, 6, 7, 1, 10, 7, 1, 7, 8, 1, 8, 0, -1, -1, -1, -1],
    [10, 6, 7, 10, 7, 1, 1, 7, 3, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 6, 1, 6, 8, 1, 8, 9, 8, 6, 7, -1, -1, -1, -1],
    [2, 6, 9, 2, 9, 1, 6, 7, 9, 0, 9, 3, 7, 3, 9, -1],
    [7, 8, 0, 7, 0, 6, 6, 0, 2, -1, -1, -1, -1, -1, -1, -1],
    [7, 3, 2, 6, 7, 2, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [2, 3, 11, 10, 6, 8, 10, 8, 9, 8, 6, 7, -1, -1, -1, -1],
    [2, 0, 7, 2, 7, 11, 0, 9, 7, 6, 7, 10, 9, 10, 7, -1],
    [1, 8, 0, 1, 7, 8, 1, 10, 7, 6, 7, 10, 2, 3, 11, -1],
    [11, 2, 1, 11, 1, 7, 10, 6, 1, 6, 7, 1, -1, -1, -1, -1],
    [8, 9, 6, 8, 6, 7, 9, 1, 6, 11, 6, 3, 1, 3, 6, -1],
    [0, 9, 1, 11, 6, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [7, 8, 0, 7, 0, 6, 3, 11, 0, 11, 6, 0, -1, -1, -1, -1],
    [7, 11, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [7, 6, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [3, 0, 8, 11, 7, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 1, 9, 11, 7, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [8, 1, 9, 8, 3, 1, 11, 7, 6, -1, -1, -1, -1, -1, -1, -1],
    [10, 1, 2, 6, 11, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 10, 3, 0, 8, 6, 11, 7, -1, -1, -1, -1, -1, -1, -1],
    [2, 9, 0, 2, 10, 9, 6, 11, 7, -1, -1, -1, -1, -1, -1, -1],
    [6, 11, 7, 2, 10, 3, 10, 8, 3, 10, 9, 8, -1, -1, -1, -1],
    [7, 2, 3, 6, 2, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [7, 0, 8, 7, 6, 0, 6, 2, 0, -1, -1, -1, -1, -1, -1, -1],
    [2, 7, 6, 2, 3, 7, 0, 1, 9, -1, -1, -1, -1, -1, -1, -1],
    [1, 6, 2, 1, 8, 6, 1, 9, 8, 8, 7, 6, -1, -1, -1, -1],
    [10, 7, 6, 10, 1, 7, 1, 3, 7, -1, -1, -1, -1, -1, -1, -1],
    [10, 7, 6, 1, 7, 10, 1, 8, 7, 1, 0, 8, -1, -1, -1, -1],
    [0, 3, 7, 0, 7, 10, 0, 10, 9, 6, 10, 7, -1, -1, -1, -1],
    [7, 6, 10, 7, 10, 8, 8, 10, 9, -1, -1, -1, -1, -1, -1, -1],
    [6, 8, 4, 11, 8, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [3, 6, 11, 3, 0, 6, 0, 4, 6, -1, -1, -1, -1, -1, -1, -1],
    [8, 6, 11, 8, 4, 6, 9, 0, 1, -1, -1, -1, -1, -1, -1, -1],
    [9, 4, 6, 9, 6, 3, 9, 3, 1, 11, 3, 6, -1, -1, -1, -1],
    [6, 8, 4, 6, 11, 8, 2, 10, 1, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 10, 3, 0, 11, 0, 6, 11, 0, 4, 6, -1, -1, -1, -1],
    [4, 11, 8, 4, 6, 11, 0, 2, 9, 2, 10, 9, -1, -1, -1, -1],
    [10, 9, 3, 10, 3, 2, 9, 4, 3, 11, 3, 6, 4, 6, 3, -1],
    [8, 2, 3, 8, 4, 2, 4, 6, 2, -1, -1, -1, -1, -1, -1, -1],
    [0, 4, 2, 4, 6, 2, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 9, 0, 2, 3, 4, 2, 4, 6, 4, 3, 8, -1, -1, -1, -1],
    [1, 9, 4, 1, 4, 2, 2, 4, 6, -1, -1, -1, -1, -1, -1, -1],
    [8, 1, 3, 8, 6, 1, 8, 4, 6, 6, 10, 1, -1, -1, -1, -1],
    [10, 1, 0, 10, 0, 6, 6, 0, 4, -1, -1, -1, -1, -1, -1, -1],
    [4, 6, 3, 4, 3, 8, 6, 10, 3, 0, 3, 9, 10, 9, 3, -1],
    [10, 9, 4, 6, 10, 4, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 9, 5, 7, 6, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 3, 4, 9, 5, 11, 7, 6, -1, -1, -1, -1, -1, -1, -1],
    [5, 0, 1, 5, 4, 0, 7, 6, 11, -1, -1, -1, -1, -1, -1, -1],
    [11, 7, 6, 8, 3, 4, 3, 5, 4, 3, 1, 5, -1, -1, -1, -1],
    [9, 5, 4, 10, 1, 2, 7, 6, 11, -1, -1, -1, -1, -1, -1, -1],
    [6, 11, 7, 1, 2, 10, 0, 8, 3, 4, 9, 5, -1, -1, -1, -1],
    [7, 6, 11, 5, 4, 10, 4, 2, 10, 4, 0, 2, -1, -1, -1, -1],
    [3, 4, 8, 3, 5, 4, 3, 2, 5, 10, 5, 2, 11, 7, 6, -1],
    [7, 2, 3, 7, 6, 2, 5, 4, 9, -1, -1, -1, -1, -1, -1, -1],
    [9, 5, 4, 0, 8, 6, 0, 6, 2, 6, 8, 7, -1, -1, -1, -1],
    [3, 6, 2, 3, 7, 6, 1, 5, 0, 5, 4, 0, -1, -1, -1, -1],
    [6, 2, 8, 6, 8, 7, 2, 1, 8, 4, 8, 5, 1, 5, 8, -1],
    [9, 5, 4, 10, 1, 6, 1, 7, 6, 1, 3, 7, -1, -1, -1, -1],
    [1, 6, 10, 1, 7, 6, 1, 0, 7, 8, 7, 0, 9, 5, 4, -1],
    [4, 0, 10, 4, 10, 5, 0, 3, 10, 6, 10, 7, 3, 7, 10, -1],
    [7, 6, 10, 7, 10, 8, 5, 4, 10, 4, 8, 10, -1, -1, -1, -1],
    [6, 9, 5, 6, 11, 9, 11, 8, 9, -1, -1, -1, -1, -1, -1, -1],
    [3, 6, 11, 0, 6, 3, 0, 5, 6, 0, 9, 5, -1, -1, -1, -1],
    [0, 11, 8, 0, 5, 11, 0, 1, 5, 5, 6, 11, -1, -1, -1, -1],
    [6, 11, 3, 6, 3, 5, 5, 3, 1, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 10, 9, 5, 11, 9, 11, 8, 11, 5, 6, -1, -1, -1, -1],
    [0, 11, 3, 0, 6, 11, 0, 9, 6, 5, 6, 9, 1, 2, 10, -1],
    [11, 8, 5, 11, 5, 6, 8, 0, 5, 10, 5, 2, 0, 2, 5, -1],
    [6, 11, 3, 6, 3, 5, 2, 10, 3, 10, 5, 3, -1, -1, -1, -1],
    [5, 8, 9, 5, 2, 8, 5, 6, 2, 3, 8, 2, -1, -1, -1, -1],
    [9, 5, 6, 9, 6, 0, 0, 6, 2, -1, -1, -1, -1, -1, -1, -1],
    [1, 5, 8, 1, 8, 0, 5, 6, 8, 3, 8, 2, 6, 2, 8, -1],
    [1, 5, 6, 2, 1, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 3, 6, 1, 6, 10, 3, 8, 6, 5, 6, 9, 8, 9, 6, -1],
    [10, 1, 0, 10, 0, 6, 9, 5, 0, 5, 6, 0, -1, -1, -1, -1],
    [0, 3, 8, 5, 6, 10, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [10, 5, 6, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [11, 5, 10, 7, 5, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [11, 5, 10, 11, 7, 5, 8, 3, 0, -1, -1, -1, -1, -1, -1, -1],
    [5, 11, 7, 5, 10, 11, 1, 9, 0, -1, -1, -1, -1, -1, -1, -1],
    [10, 7, 5, 10, 11, 7, 9, 8, 1, 8, 3, 1, -1, -1, -1, -1],
    [11, 1, 2, 11, 7, 1, 7, 5, 1, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 3, 1, 2, 7, 1, 7, 5, 7, 2, 11, -1, -1, -1, -1],
    [9, 7, 5, 9, 2, 7, 9, 0, 2, 2, 11, 7, -1, -1, -1, -1],
    [7, 5, 2, 7, 2, 11, 5, 9, 2, 3, 2, 8, 9, 8, 2, -1],
    [2, 5, 10, 2, 3, 5, 3, 7, 5, -1, -1, -1, -1, -1, -1, -1],
    [8, 2, 0, 8, 5, 2, 8, 7, 5, 10, 2, 5, -1, -1, -1, -1],
    [9, 0, 1, 5, 10, 3, 5, 3, 7, 3, 10, 2, -1, -1, -1, -1],
    [9, 8, 2, 9, 2, 1, 8, 7, 2, 10, 2, 5, 7, 5, 2, -1],
    [1, 3, 5, 3, 7, 5, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 7, 0, 7, 1, 1, 7, 5, -1, -1, -1, -1, -1, -1, -1],
    [9, 0, 3, 9, 3, 5, 5, 3, 7, -1, -1, -1, -1, -1, -1, -1],
    [9, 8, 7, 5, 9, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [5, 8, 4, 5, 10, 8, 10, 11, 8, -1, -1, -1, -1, -1, -1, -1],
    [5, 0, 4, 5, 11, 0, 5, 10, 11, 11, 3, 0, -1, -1, -1, -1],
    [0, 1, 9, 8, 4, 10, 8, 10, 11, 10, 4, 5, -1, -1, -1, -1],
    [10, 11, 4, 10, 4, 5, 11, 3, 4, 9, 4, 1, 3, 1, 4, -1],
    [2, 5, 1, 2, 8, 5, 2, 11, 8, 4, 5, 8, -1, -1, -1, -1],
    [0, 4, 11, 0, 11, 3, 4, 5, 11, 2, 11, 1, 5, 1, 11, -1],
    [0, 2, 5, 0, 5, 9, 2, 11, 5, 4, 5, 8, 11, 8, 5, -1],
    [9, 4, 5, 2, 11, 3, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [2, 5, 10, 3, 5, 2, 3, 4, 5, 3, 8, 4, -1, -1, -1, -1],
    [5, 10, 2, 5, 2, 4, 4, 2, 0, -1, -1, -1, -1, -1, -1, -1],
    [3, 10, 2, 3, 5, 10, 3, 8, 5, 4, 5, 8, 0, 1, 9, -1],
    [5, 10, 2, 5, 2, 4, 1, 9, 2, 9, 4, 2, -1, -1, -1, -1],
    [8, 4, 5, 8, 5, 3, 3, 5, 1, -1, -1, -1, -1, -1, -1, -1],
    [0, 4, 5, 1, 0, 5, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [8, 4, 5, 8, 5, 3, 9, 0, 5, 0, 3, 5, -1, -1, -1, -1],
    [9, 4, 5, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 11, 7, 4, 9, 11, 9, 10, 11, -1, -1, -1, -1, -1, -1, -1],
    [0, 8, 3, 4, 9, 7, 9, 11, 7, 9, 10, 11, -1, -1, -1, -1],
    [1, 10, 11, 1, 11, 4, 1, 4, 0, 7, 4, 11, -1, -1, -1, -1],
    [3, 1, 4, 3, 4, 8, 1, 10, 4, 7, 4, 11, 10, 11, 4, -1],
    [4, 11, 7, 9, 11, 4, 9, 2, 11, 9, 1, 2, -1, -1, -1, -1],
    [9, 7, 4, 9, 11, 7, 9, 1, 11, 2, 11, 1, 0, 8, 3, -1],
    [11, 7, 4, 11, 4, 2, 2, 4, 0, -1, -1, -1, -1, -1, -1, -1],
    [11, 7, 4, 11, 4, 2, 8, 3, 4, 3, 2, 4, -1, -1, -1, -1],
    [2, 9, 10, 2, 7, 9, 2, 3, 7, 7, 4, 9, -1, -1, -1, -1],
    [9, 10, 7, 9, 7, 4, 10, 2, 7, 8, 7, 0, 2, 0, 7, -1],
    [3, 7, 10, 3, 10, 2, 7, 4, 10, 1, 10, 0, 4, 0, 10, -1],
    [1, 10, 2, 8, 7, 4, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 9, 1, 4, 1, 7, 7, 1, 3, -1, -1, -1, -1, -1, -1, -1],
    [4, 9, 1, 4, 1, 7, 0, 8, 1, 8, 7, 1, -1, -1, -1, -1],
    [4, 0, 3, 7, 4, 3, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [4, 8, 7, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [9, 10, 8, 10, 11, 8, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [3, 0, 9, 3, 9, 11, 11, 9, 10, -1, -1, -1, -1, -1, -1, -1],
    [0, 1, 10, 0, 10, 8, 8, 10, 11, -1, -1, -1, -1, -1, -1, -1],
    [3, 1, 10, 11, 3, 10, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 2, 11, 1, 11, 9, 9, 11, 8, -1, -1, -1, -1, -1, -1, -1],
    [3, 0, 9, 3, 9, 11, 1, 2, 9, 2, 11, 9, -1, -1, -1, -1],
    [0, 2, 11, 8, 0, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [3, 2, 11, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [2, 3, 8, 2, 8, 10, 10, 8, 9, -1, -1, -1, -1, -1, -1, -1],
    [9, 10, 2, 0, 9, 2, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [2, 3, 8, 2, 8, 10, 0, 1, 8, 1, 10, 8, -1, -1, -1, -1],
    [1, 10, 2, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [1, 3, 8, 9, 1, 8, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 9, 1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [0, 3, 8, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
    [-1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1],
];

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    /// Samples `f` on `n` points per axis over [lo, hi]^3.
    fn sample(n: usize, lo: f32, hi: f32, f: impl Fn([f32; 3]) -> f32) -> (Vec<f32>, f32) {
        let h = (hi - lo) / (n - 1) as f32;
        let mut values = Vec::with_capacity(n * n * n);
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = [lo + h * i as f32, lo + h * j as f32, lo + h * k as f32];
                    values.push(f(p));
                }
            }
        }
        (values, h)
    }

    fn grid(n: usize, lo: f32, h: f32, values: &[f32]) -> ScalarGrid<'_> {
        ScalarGrid {
            dims: [n; 3],
            origin: [lo; 3],
            spacing: [h; 3],
            values,
        }
    }

    fn extract(n: usize, lo: f32, hi: f32, f: impl Fn([f32; 3]) -> f32) -> (McMesh, f32) {
        let (values, h) = sample(n, lo, hi, f);
        let mesh = marching_cubes(&grid(n, lo, h, &values), 0.0).unwrap();
        (mesh, h)
    }

    fn norm(p: [f32; 3]) -> f32 {
        (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
    }

    fn sphere(r: f32) -> impl Fn([f32; 3]) -> f32 {
        move |p| norm(p) - r
    }

    fn boxed(half: [f32; 3]) -> impl Fn([f32; 3]) -> f32 {
        move |p| {
            let q = [0, 1, 2].map(|a| p[a].abs() - half[a]);
            let outside = norm(q.map(|x| x.max(0.0)));
            let inside = q[0].max(q[1]).max(q[2]).min(0.0);
            outside + inside
        }
    }

    fn torus(big: f32, small: f32) -> impl Fn([f32; 3]) -> f32 {
        move |p| {
            let ring = (p[0] * p[0] + p[1] * p[1]).sqrt() - big;
            (ring * ring + p[2] * p[2]).sqrt() - small
        }
    }

    fn sub(a: [f32; 3], b: [f32; 3]) -> [f64; 3] {
        [0, 1, 2].map(|i| f64::from(a[i]) - f64::from(b[i]))
    }

    fn cross(u: [f64; 3], v: [f64; 3]) -> [f64; 3] {
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    }

    fn dot(u: [f64; 3], v: [f64; 3]) -> f64 {
        u[0] * v[0] + u[1] * v[1] + u[2] * v[2]
    }

    /// Number of triangles using each undirected edge, and checks that no directed edge is used
    /// twice (consistent orientation).
    fn edge_uses(mesh: &McMesh) -> HashMap<(u32, u32), usize> {
        let mut directed = HashSet::new();
        let mut uses = HashMap::new();
        for t in &mesh.triangles {
            for m in 0..3 {
                let (a, b) = (t[m], t[(m + 1) % 3]);
                assert!(
                    directed.insert((a, b)),
                    "directed edge {a}->{b} used twice: inconsistent orientation"
                );
                *uses.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        uses
    }

    /// Asserts a closed, consistently oriented, edge-manifold mesh and returns V - E + F.
    fn assert_watertight(mesh: &McMesh) -> i64 {
        assert!(!mesh.triangles.is_empty(), "mesh is empty");
        let uses = edge_uses(mesh);
        for (&(a, b), &n) in &uses {
            assert_eq!(n, 2, "edge {a}-{b} is used by {n} triangles, expected 2");
        }
        let used: HashSet<u32> = mesh.triangles.iter().flatten().copied().collect();
        assert_eq!(used.len(), mesh.positions.len(), "unreferenced vertices");
        mesh.positions.len() as i64 - uses.len() as i64 + mesh.triangles.len() as i64
    }

    fn assert_no_degenerate(mesh: &McMesh) {
        for t in &mesh.triangles {
            assert!(
                t[0] != t[1] && t[1] != t[2] && t[0] != t[2],
                "repeated index {t:?}"
            );
            for &i in t {
                assert!((i as usize) < mesh.positions.len(), "index out of range");
            }
            let [p, q, r] = t.map(|i| mesh.positions[i as usize]);
            let n = cross(sub(q, p), sub(r, p));
            assert!(
                dot(n, n) > 0.0,
                "zero-area triangle {t:?}: {p:?} {q:?} {r:?}"
            );
        }
    }

    /// Sum of signed tetrahedron volumes from the origin.
    fn signed_volume(mesh: &McMesh) -> f64 {
        mesh.triangles
            .iter()
            .map(|t| {
                let [p, q, r] = t.map(|i| mesh.positions[i as usize].map(f64::from));
                dot(p, cross(q, r)) / 6.0
            })
            .sum()
    }

    fn check_sphere(n: usize) -> (McMesh, f32) {
        let r = 0.3;
        let (mesh, h) = extract(n, -0.5, 0.5, sphere(r));
        assert!(!mesh.triangles.is_empty());
        assert_eq!(
            assert_watertight(&mesh),
            2,
            "Euler characteristic of a sphere"
        );
        assert_no_degenerate(&mesh);
        for &p in &mesh.positions {
            let d = (norm(p) - r).abs();
            assert!(d < 0.5 * h, "vertex {p:?} is {d} from the sphere (h = {h})");
        }
        let vol = signed_volume(&mesh);
        assert!(
            vol > 0.0,
            "signed volume {vol} not positive: inward orientation"
        );
        (mesh, h)
    }

    #[test]
    fn sphere_33_is_closed_genus_0_and_accurate() {
        check_sphere(33);
    }

    #[test]
    fn sphere_64_volume_within_3_percent() {
        let (mesh, _) = check_sphere(64);
        let exact = 4.0 / 3.0 * std::f64::consts::PI * 0.3f64.powi(3);
        let vol = signed_volume(&mesh);
        let rel = (vol - exact).abs() / exact;
        assert!(rel < 0.03, "volume {vol} vs {exact}: relative error {rel}");
    }

    #[test]
    fn sphere_normals_point_outwards() {
        let (mesh, _) = extract(33, -0.5, 0.5, sphere(0.3));
        for t in &mesh.triangles {
            let [p, q, r] = t.map(|i| mesh.positions[i as usize]);
            let normal = cross(sub(q, p), sub(r, p));
            let centroid =
                [0, 1, 2].map(|a| (f64::from(p[a]) + f64::from(q[a]) + f64::from(r[a])) / 3.0);
            assert!(dot(normal, centroid) > 0.0, "triangle {t:?} faces inwards");
        }
    }

    #[test]
    fn off_centre_sphere_with_anisotropic_grid() {
        let (c, r) = ([0.05f32, -0.1, 0.12], 0.25f32);
        let dims = [30, 41, 23];
        let origin = [-0.5f32, -0.55, -0.45];
        let spacing = [1.0 / 29.0, 1.1 / 40.0, 0.9 / 22.0];
        let mut values = Vec::new();
        for k in 0..dims[2] {
            for j in 0..dims[1] {
                for i in 0..dims[0] {
                    let p = [i, j, k].map(|x| x as f32);
                    let q = [0, 1, 2].map(|a| origin[a] + spacing[a] * p[a] - c[a]);
                    values.push(norm(q) - r);
                }
            }
        }
        let g = ScalarGrid {
            dims,
            origin,
            spacing,
            values: &values,
        };
        let mesh = marching_cubes(&g, 0.0).unwrap();
        assert_eq!(assert_watertight(&mesh), 2);
        assert_no_degenerate(&mesh);
        let hmax = spacing.iter().fold(0.0f32, |m, &h| m.max(h));
        for &p in &mesh.positions {
            let d = (norm([0, 1, 2].map(|a| p[a] - c[a])) - r).abs();
            assert!(d < 0.5 * hmax, "vertex {p:?} is {d} off the sphere");
        }
        assert!(signed_volume(&mesh) > 0.0);
    }

    #[test]
    fn box_is_watertight_genus_0() {
        let (mesh, h) = extract(40, -0.5, 0.5, boxed([0.25, 0.18, 0.31]));
        assert_eq!(assert_watertight(&mesh), 2);
        assert_no_degenerate(&mesh);
        let exact = 8.0 * 0.25 * 0.18 * 0.31;
        let vol = signed_volume(&mesh);
        assert!(
            vol > 0.0 && (vol - exact).abs() < 6.0 * f64::from(h) * 0.5,
            "{vol} vs {exact}"
        );
    }

    #[test]
    fn torus_is_watertight_genus_1() {
        let (mesh, _) = extract(48, -0.5, 0.5, torus(0.25, 0.1));
        assert_eq!(
            assert_watertight(&mesh),
            0,
            "Euler characteristic of a torus"
        );
        assert_no_degenerate(&mesh);
        let exact = 2.0 * std::f64::consts::PI.powi(2) * 0.25 * 0.1f64.powi(2);
        let vol = signed_volume(&mesh);
        assert!((vol - exact).abs() / exact < 0.05, "{vol} vs {exact}");
    }

    #[test]
    fn nonzero_level_offsets_surface() {
        // The 0.1 level set of a 0.2-sphere is the 0.3-sphere.
        let (values, h) = sample(33, -0.5, 0.5, sphere(0.2));
        let mesh = marching_cubes(&grid(33, -0.5, h, &values), 0.1).unwrap();
        assert_eq!(assert_watertight(&mesh), 2);
        for &p in &mesh.positions {
            assert!((norm(p) - 0.3).abs() < 0.5 * h);
        }
    }

    #[test]
    fn edge_table_matches_its_definition() {
        let (a, b) = (
            [0, 1, 2, 3, 4, 5, 6, 7, 0, 1, 2, 3],
            [1, 2, 3, 0, 5, 6, 7, 4, 4, 5, 6, 7],
        );
        // The corner numbering used by EDGE_GEOMETRY agrees with CORNER_OFFSETS.
        for e in 0..12 {
            let (lo, axis) = EDGE_GEOMETRY[e];
            let (p, q) = (CORNER_OFFSETS[a[e]], CORNER_OFFSETS[b[e]]);
            let (lo_corner, hi_corner) = if p <= q { (p, q) } else { (q, p) };
            assert_eq!(lo_corner, lo, "edge {e} lower corner");
            let mut step = lo;
            step[axis] += 1;
            assert_eq!(hi_corner, step, "edge {e} upper corner");
        }
        for (case, &entry) in EDGE_TABLE.iter().enumerate() {
            let mut expected = 0u16;
            for e in 0..12 {
                if (case >> a[e]) & 1 != (case >> b[e]) & 1 {
                    expected |= 1 << e;
                }
            }
            assert_eq!(entry, expected, "EDGE_TABLE[{case}]");
        }
    }

    #[test]
    fn triangle_table_is_consistent_with_edge_table() {
        let mut total = 0;
        for case in 0..256usize {
            let row = &TRI_TABLE[case];
            let len = row.iter().position(|&e| e < 0).unwrap_or(16);
            assert!(len % 3 == 0 && len <= 15, "case {case}: {len} entries");
            assert!(
                row[len..].iter().all(|&e| e == -1),
                "case {case}: junk after -1"
            );
            let mut used = 0u16;
            for &e in &row[..len] {
                assert!((0..12).contains(&e), "case {case}: edge {e}");
                used |= 1 << e;
            }
            for tri in row[..len].chunks_exact(3) {
                assert!(
                    tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2],
                    "case {case}"
                );
            }
            assert_eq!(
                used, EDGE_TABLE[case],
                "case {case}: edges used vs edge table"
            );
            let comp = &TRI_TABLE[255 - case];
            let comp_used = comp
                .iter()
                .take_while(|&&e| e >= 0)
                .fold(0u16, |m, &e| m | 1 << e);
            assert_eq!(used, comp_used, "cases {case} and {} differ", 255 - case);
            total += len / 3;
        }
        assert_eq!(total, 820, "Bourke's table has 820 triangles in all");
    }

    /// Deterministic pseudo-random numbers in [0, 1) (SplitMix64).
    fn random_values(n: usize, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..n)
            .map(|_| {
                s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
                let mut z = s;
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
            })
            .collect()
    }

    /// Random fields exercise every table case; interior edges must be shared by exactly two
    /// consistently oriented triangles and only edges on the grid boundary may be open.
    #[test]
    fn random_fields_give_oriented_manifold_away_from_boundary() {
        let n = 9;
        let mut seen = [false; 256];
        for seed in 0..40u64 {
            let values: Vec<f32> = random_values(n * n * n, seed)
                .iter()
                .map(|&r| (r * 2.0 - 1.0) as f32)
                .collect();
            for k in 0..n - 1 {
                for j in 0..n - 1 {
                    for i in 0..n - 1 {
                        let mut case = 0;
                        for (c, o) in CORNER_OFFSETS.iter().enumerate() {
                            let idx = i + o[0] + n * (j + o[1] + n * (k + o[2]));
                            if values[idx] < 0.0 {
                                case |= 1 << c;
                            }
                        }
                        seen[case] = true;
                    }
                }
            }
            let g = grid(n, 0.0, 1.0, &values);
            let mesh = marching_cubes(&g, 0.0).unwrap();
            assert_no_degenerate(&mesh);
            let on_boundary = |p: [f32; 3]| p.iter().any(|&x| x == 0.0 || x == (n - 1) as f32);
            for (&(a, b), &uses) in &edge_uses(&mesh) {
                let (pa, pb) = (mesh.positions[a as usize], mesh.positions[b as usize]);
                match uses {
                    2 => {}
                    1 => assert!(
                        on_boundary(pa) && on_boundary(pb),
                        "seed {seed}: open edge {pa:?}-{pb:?} inside the grid"
                    ),
                    _ => panic!("seed {seed}: edge {pa:?}-{pb:?} used {uses} times"),
                }
            }
        }
        let missing: Vec<usize> = (0..256).filter(|&c| !seen[c]).collect();
        assert!(missing.is_empty(), "cases never exercised: {missing:?}");
    }

    #[test]
    fn shared_edges_give_bitwise_identical_vertices() {
        // Every vertex position occurs once: two cells never create separate copies of a vertex.
        let (mesh, _) = extract(33, -0.5, 0.5, torus(0.22, 0.12));
        let mut seen = HashSet::new();
        for p in &mesh.positions {
            assert!(seen.insert(p.map(f32::to_bits)), "duplicate vertex {p:?}");
        }
    }

    #[test]
    fn samples_exactly_on_the_level_are_welded() {
        // |x| + |y| + |z| - 3 on an integer grid: many samples are exactly 0, so many vertices
        // land on grid corners; they must be welded, with no degenerate triangles left.
        let n = 9;
        let mut values = Vec::new();
        for k in 0..n {
            for j in 0..n {
                for i in 0..n {
                    let p = [i, j, k].map(|x| (x as f32 - 4.0).abs());
                    values.push(p[0] + p[1] + p[2] - 3.0);
                }
            }
        }
        let mesh = marching_cubes(&grid(n, -4.0, 1.0, &values), 0.0).unwrap();
        assert_no_degenerate(&mesh);
        assert_eq!(assert_watertight(&mesh), 2);
        let mut seen = HashSet::new();
        for p in &mesh.positions {
            assert!(seen.insert(p.map(f32::to_bits)), "duplicate vertex {p:?}");
            assert!((p[0].abs() + p[1].abs() + p[2].abs() - 3.0).abs() < 1e-6);
        }
        assert!(signed_volume(&mesh) > 0.0);
    }

    #[test]
    fn plane_through_sample_layer() {
        // The field z - 0.0 is exactly zero on the middle sample plane.
        let n = 5;
        let (values, h) = sample(n, -1.0, 1.0, |p| p[2]);
        let mesh = marching_cubes(&grid(n, -1.0, h, &values), 0.0).unwrap();
        assert_no_degenerate(&mesh);
        assert_eq!(mesh.positions.len(), n * n);
        assert_eq!(mesh.triangles.len(), 2 * (n - 1) * (n - 1));
        for t in &mesh.triangles {
            let [p, q, r] = t.map(|i| mesh.positions[i as usize]);
            assert!(p[2] == 0.0 && q[2] == 0.0 && r[2] == 0.0);
            // Outside is +z.
            assert!(cross(sub(q, p), sub(r, p))[2] > 0.0);
        }
    }

    #[test]
    fn surface_crossing_the_grid_boundary_is_open_but_fine() {
        let (mesh, _) = extract(17, -0.5, 0.5, sphere(0.6));
        assert!(!mesh.triangles.is_empty());
        assert_no_degenerate(&mesh);
        let uses = edge_uses(&mesh);
        assert!(uses.values().any(|&n| n == 1), "expected an open mesh");
        assert!(uses.values().all(|&n| n <= 2));
        // Touching the boundary exactly.
        let (mesh, _) = extract(17, -0.5, 0.5, sphere(0.5));
        assert_no_degenerate(&mesh);
    }

    #[test]
    fn all_inside_or_all_outside_is_empty() {
        for v in [-1.0f32, 1.0, 0.0] {
            let values = vec![v; 4 * 3 * 5];
            let g = ScalarGrid {
                dims: [4, 3, 5],
                origin: [0.0; 3],
                spacing: [0.1, 0.2, 0.3],
                values: &values,
            };
            assert_eq!(
                marching_cubes(&g, 0.0).unwrap(),
                McMesh::default(),
                "value {v}"
            );
        }
        // Minimal 2x2x2 grid with one inside corner: one triangle.
        let mut values = vec![1.0f32; 8];
        values[0] = -1.0;
        let g = grid(2, 0.0, 1.0, &values);
        let mesh = marching_cubes(&g, 0.0).unwrap();
        assert_eq!(mesh.triangles.len(), 1);
        assert_eq!(mesh.positions.len(), 3);
        assert_no_degenerate(&mesh);
    }

    #[test]
    fn non_finite_samples_do_not_panic() {
        let (mut values, h) = sample(17, -0.5, 0.5, sphere(0.3));
        for (idx, v) in values.iter_mut().enumerate() {
            match idx % 7 {
                0 => *v = f32::NAN,
                3 => *v = f32::INFINITY,
                5 if idx % 3 == 0 => *v = f32::NEG_INFINITY,
                _ => {}
            }
        }
        let mesh = marching_cubes(&grid(17, -0.5, h, &values), 0.0).unwrap();
        assert!(!mesh.triangles.is_empty());
        assert_no_degenerate(&mesh);
        for p in &mesh.positions {
            assert!(p.iter().all(|x| x.is_finite()));
            assert!(norm(*p) <= 0.3 + 2.0 * h);
        }
        // (Manifoldness is not promised here: a vertex next to a non-finite sample snaps onto
        // the finite corner, so several sheets may meet there.)
        // All NaN: nothing is inside.
        let nan = vec![f32::NAN; 27];
        assert!(
            marching_cubes(&grid(3, 0.0, 1.0, &nan), 0.0)
                .unwrap()
                .triangles
                .is_empty()
        );
        // Extreme finite values must not overflow the interpolation.
        let mut big = vec![f32::MAX; 8];
        big[0] = -f32::MAX;
        let mesh = marching_cubes(&grid(2, 0.0, 1.0, &big), 0.0).unwrap();
        assert_eq!(mesh.triangles.len(), 1);
        assert!(mesh.positions.iter().flatten().all(|x| x.is_finite()));
    }

    #[test]
    fn invalid_grids_are_rejected_with_the_field_named() {
        let values = vec![0.0f32; 27];
        let ok = grid(3, 0.0, 1.0, &values);
        assert!(ok.validate().is_ok());
        let check = |g: ScalarGrid<'_>, needles: &[&str]| {
            let err = marching_cubes(&g, 0.0).unwrap_err();
            for needle in needles {
                assert!(err.contains(needle), "{err:?} should mention {needle:?}");
            }
            assert_eq!(g.validate().unwrap_err(), err);
        };
        check(
            ScalarGrid {
                dims: [3, 1, 9],
                ..grid(3, 0.0, 1.0, &values)
            },
            &["dims[1]", ">= 2", "got 1"],
        );
        check(
            ScalarGrid {
                spacing: [1.0, 1.0, 0.0],
                ..grid(3, 0.0, 1.0, &values)
            },
            &["spacing[2]", "> 0", "got 0"],
        );
        check(
            ScalarGrid {
                spacing: [-0.5, 1.0, 1.0],
                ..grid(3, 0.0, 1.0, &values)
            },
            &["spacing[0]", "got -0.5"],
        );
        check(
            ScalarGrid {
                spacing: [1.0, f32::NAN, 1.0],
                ..grid(3, 0.0, 1.0, &values)
            },
            &["spacing[1]", "finite", "NaN"],
        );
        check(
            ScalarGrid {
                origin: [0.0, 0.0, f32::INFINITY],
                ..grid(3, 0.0, 1.0, &values)
            },
            &["origin[2]", "finite", "inf"],
        );
        check(
            grid(3, 0.0, 1.0, &values[..26]),
            &["values.len()", "27", "got 26"],
        );
        check(
            ScalarGrid {
                dims: [usize::MAX, 2, 2],
                ..grid(3, 0.0, 1.0, &values)
            },
            &["dims", "overflows"],
        );
        let err = marching_cubes(&ok, f32::NAN).unwrap_err();
        assert!(err.contains("level") && err.contains("NaN"), "{err}");
    }

    /// Throughput on a 161^3 sphere grid; run with
    /// `cargo test --release -- --ignored --nocapture throughput`.
    #[test]
    #[ignore = "benchmark; run explicitly in release mode"]
    fn throughput_161_sphere() {
        let n = 161;
        let (values, h) = sample(n, -0.5, 0.5, sphere(0.3));
        let g = grid(n, -0.5, h, &values);
        let cells = ((n - 1) * (n - 1) * (n - 1)) as f64;
        let mut best = f64::INFINITY;
        let mut mesh = McMesh::default();
        for _ in 0..5 {
            let start = std::time::Instant::now();
            mesh = marching_cubes(&g, 0.0).unwrap();
            best = best.min(start.elapsed().as_secs_f64());
        }
        println!(
            "161^3 sphere: {} vertices, {} triangles, best {:.2} ms, {:.1} M cells/s",
            mesh.positions.len(),
            mesh.triangles.len(),
            best * 1e3,
            cells / best / 1e6
        );
        assert_eq!(assert_watertight(&mesh), 2);
        // A dense surface (gyroid, ~10 periods across the grid) for a busier workload.
        let f = 10.0 * std::f32::consts::TAU;
        let (values, h) = sample(n, -0.5, 0.5, |p| {
            let [x, y, z] = p.map(|c| c * f);
            x.sin() * y.cos() + y.sin() * z.cos() + z.sin() * x.cos()
        });
        let g = grid(n, -0.5, h, &values);
        let mut best = f64::INFINITY;
        for _ in 0..5 {
            let start = std::time::Instant::now();
            mesh = marching_cubes(&g, 0.0).unwrap();
            best = best.min(start.elapsed().as_secs_f64());
        }
        println!(
            "161^3 gyroid: {} vertices, {} triangles, best {:.2} ms, {:.1} M cells/s",
            mesh.positions.len(),
            mesh.triangles.len(),
            best * 1e3,
            cells / best / 1e6
        );
    }
}
