//! ParaView particle frames: VTK XML PolyData (`.vtp`, inline base64 binary) and a `.pvd` time index.

use std::fmt::Write as _;
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use sph_core::dim::Vector;

use sph_core::atomic::{write_atomic, write_atomic_with};

/// Per-particle arrays of one frame; every non-empty array has one entry per position.
pub struct FrameFields<'a> {
    pub positions: &'a [Vector],
    pub velocity: &'a [Vector],
    pub density: &'a [f64],
    pub pressure: &'a [f64],
    /// May be empty: then the array is omitted.
    pub neighbours: &'a [u32],
    /// More named point arrays.
    pub extra_scalars: &'a [(&'a str, &'a [f64])],
}

/// Writes one frame as a `.vtp` file (2D points at z = 0, one vertex cell per point),
/// atomically.
///
/// The document is streamed to the file (base64 in small chunks), so writing a frame
/// holds no copy of it in memory.
///
/// Fails with `InvalidInput` if an array length differs from the number of positions.
pub fn write_vtp(path: &Path, f: &FrameFields) -> io::Result<()> {
    check_frame(f)?;
    write_atomic_with(path, |tmp| {
        let mut w = io::BufWriter::new(std::fs::File::create(tmp)?);
        write_vtp_document(&mut w, f)?;
        w.flush()
    })
}

/// Checks every array of `f` against the number of positions.
fn check_frame(f: &FrameFields) -> io::Result<()> {
    let n = f.positions.len();
    check_len("velocity", f.velocity.len(), n)?;
    check_len("density", f.density.len(), n)?;
    check_len("pressure", f.pressure.len(), n)?;
    if !f.neighbours.is_empty() {
        check_len("neighbours", f.neighbours.len(), n)?;
    }
    for (name, values) in f.extra_scalars {
        check_len(name, values.len(), n)?;
    }
    i32::try_from(n).map_err(|_| invalid(format!("too many points: {n}")))?;
    Ok(())
}

fn write_vtp_document(w: &mut impl Write, f: &FrameFields) -> io::Result<()> {
    let n = f.positions.len();
    let n_i32 = n as i32; // checked by `check_frame`
    w.write_all(b"<?xml version=\"1.0\"?>\n")?;
    w.write_all(
        b"<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt32\">\n",
    )?;
    w.write_all(b"  <PolyData>\n")?;
    writeln!(
        w,
        "    <Piece NumberOfPoints=\"{n}\" NumberOfVerts=\"{n}\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">"
    )?;

    w.write_all(b"      <PointData Scalars=\"pressure\" Vectors=\"velocity\">\n")?;
    data_array(
        w,
        "Float64",
        "velocity",
        3,
        f.velocity.iter().map(|&v| xyz(v)),
    )?;
    data_array(
        w,
        "Float64",
        "density",
        1,
        f.density.iter().map(|v| v.to_le_bytes()),
    )?;
    data_array(
        w,
        "Float64",
        "pressure",
        1,
        f.pressure.iter().map(|v| v.to_le_bytes()),
    )?;
    if !f.neighbours.is_empty() {
        let counts = f.neighbours.iter().map(|v| v.to_le_bytes());
        data_array(w, "UInt32", "neighbours", 1, counts)?;
    }
    for (name, values) in f.extra_scalars {
        let values = values.iter().map(|v| v.to_le_bytes());
        data_array(w, "Float64", &xml_escape(name), 1, values)?;
    }
    w.write_all(b"      </PointData>\n")?;

    w.write_all(b"      <Points>\n")?;
    data_array(
        w,
        "Float64",
        "Points",
        3,
        f.positions.iter().map(|&p| xyz(p)),
    )?;
    w.write_all(b"      </Points>\n")?;

    w.write_all(b"      <Verts>\n")?;
    let connectivity = (0..n_i32).map(i32::to_le_bytes);
    data_array(w, "Int32", "connectivity", 1, connectivity)?;
    let offsets = (0..n_i32).map(|k| (k + 1).to_le_bytes());
    data_array(w, "Int32", "offsets", 1, offsets)?;
    w.write_all(b"      </Verts>\n")?;

    w.write_all(b"    </Piece>\n  </PolyData>\n</VTKFile>\n")
}

/// A vector as the little-endian bytes of (x, y, z), z = 0 in 2D.
fn xyz(v: Vector) -> [u8; 24] {
    let mut b = [0; 24];
    for (k, c) in v.to_array().into_iter().enumerate() {
        b[8 * k..8 * k + 8].copy_from_slice(&c.to_le_bytes());
    }
    b
}

/// One `<DataArray format="binary">`: base64 of (UInt32 byte count ++ the items'
/// little-endian bytes), streamed.
fn data_array<const B: usize>(
    w: &mut impl Write,
    ty: &str,
    name: &str,
    components: u32,
    items: impl ExactSizeIterator<Item = [u8; B]>,
) -> io::Result<()> {
    let len = u32::try_from(items.len() * B)
        .map_err(|_| invalid(format!("array {name} exceeds 4 GiB")))?;
    write!(
        w,
        "        <DataArray type=\"{ty}\" Name=\"{name}\" NumberOfComponents=\"{components}\" format=\"binary\">"
    )?;
    let mut encoder = Base64::new(w);
    encoder.push(&len.to_le_bytes())?;
    // Items gathered into a small buffer, encoded a buffer at a time.
    let mut stage = [0u8; 768];
    let mut k = 0;
    for item in items {
        if k + B > stage.len() {
            encoder.push(&stage[..k])?;
            k = 0;
        }
        stage[k..k + B].copy_from_slice(&item);
        k += B;
    }
    encoder.push(&stage[..k])?;
    encoder.finish()?;
    w.write_all(b"</DataArray>\n")
}

/// Streaming standard base64 (RFC 4648, with padding) into a writer.
struct Base64<'w, W: Write> {
    out: &'w mut W,
    pending: [u8; 3],
    n_pending: usize,
    /// Encoded characters not yet written.
    text: [u8; 1024],
    n_text: usize,
}

const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";

impl<'w, W: Write> Base64<'w, W> {
    fn new(out: &'w mut W) -> Self {
        Self {
            out,
            pending: [0; 3],
            n_pending: 0,
            text: [0; 1024],
            n_text: 0,
        }
    }

    fn push(&mut self, mut data: &[u8]) -> io::Result<()> {
        if self.n_pending > 0 {
            while self.n_pending < 3 {
                let Some((&b, rest)) = data.split_first() else {
                    return Ok(());
                };
                self.pending[self.n_pending] = b;
                self.n_pending += 1;
                data = rest;
            }
            let p = self.pending;
            self.triple(p[0], p[1], p[2], 4)?;
            self.n_pending = 0;
        }
        let mut chunks = data.chunks_exact(3);
        for c in &mut chunks {
            self.triple(c[0], c[1], c[2], 4)?;
        }
        let rest = chunks.remainder();
        self.pending[..rest.len()].copy_from_slice(rest);
        self.n_pending = rest.len();
        Ok(())
    }

    fn finish(mut self) -> io::Result<()> {
        let p = self.pending;
        match self.n_pending {
            1 => self.triple(p[0], 0, 0, 2)?,
            2 => self.triple(p[0], p[1], 0, 3)?,
            _ => {}
        }
        if self.n_pending > 0 {
            for _ in self.n_pending..3 {
                self.put(b'=')?;
            }
        }
        self.out.write_all(&self.text[..self.n_text])
    }

    /// The first `chars` base64 characters of the 24-bit group `a b c`.
    fn triple(&mut self, a: u8, b: u8, c: u8, chars: usize) -> io::Result<()> {
        let v = (u32::from(a) << 16) | (u32::from(b) << 8) | u32::from(c);
        for i in 0..chars {
            self.put(B64[((v >> (18 - 6 * i)) & 63) as usize])?;
        }
        Ok(())
    }

    fn put(&mut self, ch: u8) -> io::Result<()> {
        if self.n_text == self.text.len() {
            self.out.write_all(&self.text)?;
            self.n_text = 0;
        }
        self.text[self.n_text] = ch;
        self.n_text += 1;
        Ok(())
    }
}

fn check_len(name: &str, len: usize, n: usize) -> io::Result<()> {
    if len == n {
        Ok(())
    } else {
        Err(invalid(format!(
            "array {name} has {len} entries, expected {n}"
        )))
    }
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            _ => out.push(c),
        }
    }
    out
}

/// Writes straight segments (walls) as a VTK PolyData file of lines, atomically.
pub fn write_segments_vtp(path: &Path, segments: &[(Vector, Vector)]) -> io::Result<()> {
    let n = segments.len();
    let mut s = String::with_capacity(400 + 120 * n);
    s.push_str("<?xml version=\"1.0\"?>\n<VTKFile type=\"PolyData\" version=\"1.0\" byte_order=\"LittleEndian\">\n  <PolyData>\n");
    let _ = writeln!(
        s,
        "    <Piece NumberOfPoints=\"{}\" NumberOfVerts=\"0\" NumberOfLines=\"{n}\" NumberOfStrips=\"0\" NumberOfPolys=\"0\">",
        2 * n
    );
    s.push_str("      <Points>\n        <DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n");
    for (a, b) in segments {
        let [a, b] = [a, b].map(|v| {
            let mut p = [0.0; 3];
            p[..v.to_array().len()].copy_from_slice(&v.to_array());
            p
        });
        let _ = writeln!(
            s,
            "          {} {} {} {} {} {}",
            a[0], a[1], a[2], b[0], b[1], b[2]
        );
    }
    s.push_str("        </DataArray>\n      </Points>\n      <Lines>\n");
    s.push_str(
        "        <DataArray type=\"Int32\" Name=\"connectivity\" format=\"ascii\">\n          ",
    );
    for k in 0..2 * n {
        let _ = write!(s, "{k} ");
    }
    s.push_str("\n        </DataArray>\n        <DataArray type=\"Int32\" Name=\"offsets\" format=\"ascii\">\n          ");
    for k in 1..=n {
        let _ = write!(s, "{} ", 2 * k);
    }
    s.push_str("\n        </DataArray>\n      </Lines>\n    </Piece>\n  </PolyData>\n</VTKFile>\n");
    if segments
        .iter()
        .any(|(a, b)| !a.is_finite() || !b.is_finite())
    {
        return Err(invalid(format!(
            "non-finite wall end in {}",
            path.display()
        )));
    }
    write_atomic(path, s.as_bytes())
}

/// A ParaView `.pvd` collection listing frames by time; rewritten atomically on every push.
pub struct PvdIndex {
    path: PathBuf,
    entries: Vec<(f64, String)>,
}

impl PvdIndex {
    /// An empty index to be written at `path` (nothing is written until the first push).
    pub fn new(path: PathBuf) -> Self {
        Self {
            path,
            entries: Vec::new(),
        }
    }

    /// Adds (time, file name relative to the pvd's folder) and rewrites the .pvd.
    pub fn push(&mut self, time: f64, file: &str) -> io::Result<()> {
        if !time.is_finite() {
            return Err(invalid(format!("non-finite frame time {time} for {file}")));
        }
        self.entries.push((time, file.to_owned()));
        write_atomic(&self.path, self.document().as_bytes())
    }

    /// Replaces the entries (a run resuming from a checkpoint) and rewrites the .pvd
    /// when there are any.
    pub fn restore(&mut self, entries: Vec<(f64, String)>) -> io::Result<()> {
        self.entries = entries;
        if self.entries.is_empty() {
            return Ok(());
        }
        write_atomic(&self.path, self.document().as_bytes())
    }

    /// Path of the `.pvd` file.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Frames pushed so far, as (time, file).
    pub fn entries(&self) -> &[(f64, String)] {
        &self.entries
    }

    fn document(&self) -> String {
        let mut s = String::with_capacity(200 + 80 * self.entries.len());
        s.push_str("<?xml version=\"1.0\"?>\n");
        s.push_str("<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n");
        s.push_str("  <Collection>\n");
        for (time, file) in &self.entries {
            let _ = writeln!(
                s,
                "    <DataSet timestep=\"{time}\" group=\"\" part=\"0\" file=\"{}\"/>",
                xml_escape(file)
            );
        }
        s.push_str("  </Collection>\n</VTKFile>\n");
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use sph_core::dim;
    use std::fs;

    fn test_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("sph_core_vtk_{name}_{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn segments_file_lists_two_points_per_line() {
        let dir = test_dir("segments");
        let path = dir.join("walls.vtp");
        let segs = [
            (dim::xy(0.0, 1.0), dim::xy(0.0, 0.0)),
            (dim::xy(0.0, 0.0), dim::xy(2.0, 0.5)),
        ];
        write_segments_vtp(&path, &segs).unwrap();
        let text = fs::read_to_string(&path).unwrap();
        assert!(text.contains("NumberOfPoints=\"4\""));
        assert!(text.contains("NumberOfLines=\"2\""));
        assert!(text.contains("0 0 0 2 0.5 0"));
        assert!(text.contains("2 4 \n"));
        assert!(write_segments_vtp(&path, &[(Vector::NAN, Vector::ZERO)]).is_err());
        let _ = fs::remove_dir_all(&dir);
    }

    /// The document `write_vtp` would write, in memory.
    fn vtp_document(f: &FrameFields) -> io::Result<String> {
        check_frame(f)?;
        let mut out = Vec::new();
        write_vtp_document(&mut out, f)?;
        Ok(String::from_utf8(out).unwrap())
    }

    fn b64_decode(s: &str) -> Vec<u8> {
        let val = |c: u8| B64.iter().position(|&x| x == c).unwrap() as u32;
        let mut out = Vec::new();
        for q in s.as_bytes().chunks(4) {
            let pad = q.iter().filter(|&&c| c == b'=').count();
            let v = q.iter().fold(0u32, |acc, &c| {
                (acc << 6) | if c == b'=' { 0 } else { val(c) }
            });
            out.extend_from_slice(&v.to_be_bytes()[1..4 - pad]);
        }
        out
    }

    /// Decoded payload (after the UInt32 header) of the DataArray called `name`.
    fn array_payload(doc: &str, name: &str) -> Vec<u8> {
        let tag = format!("Name=\"{name}\"");
        let start = doc.find(&tag).unwrap();
        let body_start = start + doc[start..].find('>').unwrap() + 1;
        let body_end = body_start + doc[body_start..].find("</DataArray>").unwrap();
        let bytes = b64_decode(&doc[body_start..body_end]);
        let header = u32::from_le_bytes(bytes[..4].try_into().unwrap()) as usize;
        assert_eq!(header, bytes.len() - 4, "byte-count header of {name}");
        bytes[4..].to_vec()
    }

    fn f64s(bytes: &[u8]) -> Vec<f64> {
        bytes
            .chunks(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    #[test]
    fn base64_matches_rfc4648_vectors() {
        for (input, expected) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            // Split pushes exercise the carry-over between calls.
            for split in 0..=input.len() {
                let mut out = Vec::new();
                let mut e = Base64::new(&mut out);
                e.push(&input.as_bytes()[..split]).unwrap();
                e.push(&input.as_bytes()[split..]).unwrap();
                e.finish().unwrap();
                let out = String::from_utf8(out).unwrap();
                assert_eq!(out, expected, "input {input:?} split {split}");
                assert_eq!(b64_decode(&out), input.as_bytes());
            }
        }
    }

    #[test]
    fn three_point_frame_and_pvd() {
        let dir = test_dir("frame");
        let mut positions = [dim::xy(0.0, 0.0), dim::xy(1.0, 0.5), dim::xy(2.0, -1.0)];
        // A z of its own in 3D (z = 0 in 2D).
        positions[2][dim::DIM - 1] = dim::pick(-1.0, 1.5);
        let velocity = [dim::xy(0.1, 0.2), Vector::ZERO, dim::xy(-3.0, 4.0)];
        let density = [1000.0, 1001.5, 999.0];
        let pressure = [0.0, 10.0, -5.0];
        let neighbours = [2, 3, 1];
        let vorticity = [0.5, 0.25, 0.125];
        let frame = FrameFields {
            positions: &positions,
            velocity: &velocity,
            density: &density,
            pressure: &pressure,
            neighbours: &neighbours,
            extra_scalars: &[("vorticity", &vorticity)],
        };
        let path = dir.join("frame_0000.vtp");
        write_vtp(&path, &frame).unwrap();
        let doc = fs::read_to_string(&path).unwrap();

        assert!(doc.contains("NumberOfPoints=\"3\""));
        assert!(doc.contains("NumberOfVerts=\"3\""));
        for name in [
            "velocity",
            "density",
            "pressure",
            "neighbours",
            "vorticity",
            "Points",
            "connectivity",
            "offsets",
        ] {
            assert!(
                doc.contains(&format!("Name=\"{name}\"")),
                "missing array {name}"
            );
        }
        for tag in [
            "VTKFile",
            "PolyData",
            "Piece",
            "PointData",
            "Points",
            "Verts",
            "DataArray",
        ] {
            let opens =
                doc.matches(&format!("<{tag}>")).count() + doc.matches(&format!("<{tag} ")).count();
            let closes = doc.matches(&format!("</{tag}>")).count();
            assert_eq!(opens, closes, "unbalanced <{tag}>");
            assert!(opens > 0);
        }
        assert_eq!(doc.matches("<DataArray ").count(), 8);

        assert_eq!(
            f64s(&array_payload(&doc, "Points")),
            [0.0, 0.0, 0.0, 1.0, 0.5, 0.0, 2.0, -1.0, dim::pick(0.0, 1.5)]
        );
        assert_eq!(
            f64s(&array_payload(&doc, "velocity"))[6..],
            [-3.0, 4.0, 0.0]
        );
        assert_eq!(f64s(&array_payload(&doc, "pressure")), pressure);
        assert_eq!(f64s(&array_payload(&doc, "vorticity")), vorticity);
        assert_eq!(
            array_payload(&doc, "neighbours"),
            [2, 0, 0, 0, 3, 0, 0, 0, 1, 0, 0, 0]
        );
        assert_eq!(
            array_payload(&doc, "offsets"),
            [1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0]
        );

        let mut pvd = PvdIndex::new(dir.join("run.pvd"));
        pvd.push(0.0, "frame_0000.vtp").unwrap();
        pvd.push(0.25, "frame_0001.vtp").unwrap();
        let index = fs::read_to_string(dir.join("run.pvd")).unwrap();
        assert!(index.contains("type=\"Collection\""));
        assert!(index.contains("timestep=\"0\" group=\"\" part=\"0\" file=\"frame_0000.vtp\""));
        assert!(index.contains("timestep=\"0.25\" group=\"\" part=\"0\" file=\"frame_0001.vtp\""));
        assert_eq!(index.matches("<DataSet ").count(), 2);
        assert!(pvd.push(f64::NAN, "bad.vtp").is_err());
        assert_eq!(pvd.entries().len(), 2);

        // Only the finished files remain: no temporaries.
        let mut names: Vec<_> = fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        names.sort();
        assert_eq!(names, ["frame_0000.vtp", "run.pvd"]);
        fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn optional_neighbours_and_length_checks() {
        let positions = [Vector::ZERO, Vector::ONE];
        let v = [Vector::ZERO; 2];
        let s = [1.0, 2.0];
        let mut frame = FrameFields {
            positions: &positions,
            velocity: &v,
            density: &s,
            pressure: &s,
            neighbours: &[],
            extra_scalars: &[],
        };
        let doc = vtp_document(&frame).unwrap();
        assert!(!doc.contains("neighbours"));
        assert_eq!(doc.matches("<DataArray ").count(), 6);

        frame.density = &s[..1];
        let err = vtp_document(&frame).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        frame.density = &s;
        let short = [1.0];
        let extras: [(&str, &[f64]); 1] = [("x", &short)];
        frame.extra_scalars = &extras;
        assert!(vtp_document(&frame).is_err());
    }

    #[test]
    fn empty_frame_is_valid() {
        let frame = FrameFields {
            positions: &[],
            velocity: &[],
            density: &[],
            pressure: &[],
            neighbours: &[],
            extra_scalars: &[],
        };
        let doc = vtp_document(&frame).unwrap();
        assert!(doc.contains("NumberOfPoints=\"0\""));
        assert!(array_payload(&doc, "Points").is_empty());
    }
}
