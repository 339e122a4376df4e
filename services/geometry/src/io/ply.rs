//! PLY, the Stanford polygon format: reading ascii and binary of either byte order, writing
//! binary little-endian or ascii.
//!
//! Reading keeps `x`, `y`, `z` of the `vertex` element and the `vertex_indices` (or
//! `vertex_index`) list of the `face` element. Every other element and property (normals,
//! colours, texture coordinates, edges, materials) is skipped by its declared type, in whatever
//! order the header lists them. Faces with more than three corners are fan-triangulated.

use std::fmt;
use std::io::{self, Write};

use nalgebra::Point3;

use super::text::{self, Lines};
use super::{Location, MeshIoError, ParsedMesh};
use crate::mesh::{LengthUnit, TriMesh};

/// How [`write_ply`](super::write_ply) encodes a file. Reading also accepts big-endian binary.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PlyEncoding {
    /// Text; each coordinate is the shortest decimal that reads back to the same `f32`.
    Ascii,
    /// Binary little-endian: compact and exact, what BOP and most tools write.
    #[default]
    BinaryLittleEndian,
}

/// Writes `mesh` (metres) as a PLY file with vertices in `unit`: `float x, y, z` and
/// `list uchar uint vertex_indices`. Writes in small pieces: give it a buffered writer.
pub fn write_ply_to(
    out: &mut dyn Write,
    mesh: &TriMesh,
    unit: LengthUnit,
    encoding: PlyEncoding,
) -> io::Result<()> {
    let format = match encoding {
        PlyEncoding::Ascii => "ascii",
        PlyEncoding::BinaryLittleEndian => "binary_little_endian",
    };
    write!(
        out,
        "ply\nformat {format} 1.0\ncomment written by Glint; lengths in {unit}\nelement vertex {}\n\
         property float x\nproperty float y\nproperty float z\nelement face {}\n\
         property list uchar uint vertex_indices\nend_header\n",
        mesh.vertices.len(),
        mesh.triangles.len()
    )?;
    let metres_per_unit = unit.metres_per_unit();
    // Dividing in f64 rounds each coordinate to f32 once.
    let in_unit = |p: &Point3<f32>| p.coords.map(|c| (f64::from(c) / metres_per_unit) as f32);
    match encoding {
        PlyEncoding::Ascii => {
            for p in &mesh.vertices {
                let v = in_unit(p);
                writeln!(out, "{} {} {}", v.x, v.y, v.z)?;
            }
            for [a, b, c] in &mesh.triangles {
                writeln!(out, "3 {a} {b} {c}")?;
            }
        }
        PlyEncoding::BinaryLittleEndian => {
            for p in &mesh.vertices {
                let mut record = [0u8; 12];
                for (bytes, c) in record.chunks_exact_mut(4).zip(in_unit(p).iter()) {
                    bytes.copy_from_slice(&c.to_le_bytes());
                }
                out.write_all(&record)?;
            }
            for triangle in &mesh.triangles {
                let mut record = [3u8; 13];
                for (bytes, v) in record[1..].chunks_exact_mut(4).zip(triangle) {
                    bytes.copy_from_slice(&v.to_le_bytes());
                }
                out.write_all(&record)?;
            }
        }
    }
    Ok(())
}

/// Writes a point cloud (metres) as binary little-endian PLY in metres: `float x, y, z` and,
/// with `normals`, `float nx, ny, nz`; no faces. Panics-free: a `normals` slice of another
/// length is an `InvalidInput` error. Give it a buffered writer.
pub fn write_ply_points_to(
    out: &mut dyn Write,
    points: &[Point3<f64>],
    normals: Option<&[nalgebra::Vector3<f64>]>,
) -> io::Result<()> {
    if let Some(n) = normals
        && n.len() != points.len()
    {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{} normals for {} points", n.len(), points.len()),
        ));
    }
    let normal_header = if normals.is_some() {
        "property float nx\nproperty float ny\nproperty float nz\n"
    } else {
        ""
    };
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment written by Glint; lengths in m\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         {normal_header}end_header\n",
        points.len()
    )?;
    for (i, p) in points.iter().enumerate() {
        let mut record = [0u8; 24];
        let mut values = [p.x, p.y, p.z, 0.0, 0.0, 0.0];
        let len = if let Some(n) = normals {
            values[3..].copy_from_slice(n[i].as_slice());
            24
        } else {
            12
        };
        for (bytes, c) in record[..len].chunks_exact_mut(4).zip(values) {
            bytes.copy_from_slice(&(c as f32).to_le_bytes());
        }
        out.write_all(&record[..len])?;
    }
    Ok(())
}

/// Whether `bytes` start with PLY's magic line.
pub(super) fn looks_like_ply(bytes: &[u8]) -> bool {
    bytes.starts_with(b"ply") && matches!(bytes.get(3), Some(b'\n' | b'\r'))
}

/// Reads a PLY file; coordinates are multiplied by `metres_per_unit`.
pub(super) fn read(
    bytes: &[u8],
    metres_per_unit: f64,
    file: &str,
) -> Result<ParsedMesh, MeshIoError> {
    let header = Header::parse(bytes, file)?;
    let roles = assign_roles(&header, file)?;
    let reader = MeshReader {
        header: &header,
        roles: &roles,
        metres_per_unit,
    };
    let mut parsed = match header.storage {
        Storage::Ascii => {
            let body = bytes.get(header.body_offset..).unwrap_or_default();
            reader.read(&mut AsciiBody::new(file, body, header.body_first_line))?
        }
        Storage::Binary { big_endian } => reader.read(&mut BinaryBody {
            file,
            bytes,
            offset: header.body_offset,
            big_endian,
            entry: Entry::default(),
        })?,
    };
    let mut warnings = header.warnings;
    warnings.append(&mut parsed.warnings);
    parsed.warnings = warnings;
    Ok(parsed)
}

/// A PLY scalar type; the header names each in two spellings (`float` or `float32`, ...).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ScalarType {
    Int8,
    Uint8,
    Int16,
    Uint16,
    Int32,
    Uint32,
    Float32,
    Float64,
}

impl ScalarType {
    fn from_name(name: &[u8]) -> Option<Self> {
        Some(match name {
            b"char" | b"int8" => Self::Int8,
            b"uchar" | b"uint8" => Self::Uint8,
            b"short" | b"int16" => Self::Int16,
            b"ushort" | b"uint16" => Self::Uint16,
            b"int" | b"int32" => Self::Int32,
            b"uint" | b"uint32" => Self::Uint32,
            b"float" | b"float32" => Self::Float32,
            b"double" | b"float64" => Self::Float64,
            _ => return None,
        })
    }

    fn size_bytes(self) -> usize {
        match self {
            Self::Int8 | Self::Uint8 => 1,
            Self::Int16 | Self::Uint16 => 2,
            Self::Int32 | Self::Uint32 | Self::Float32 => 4,
            Self::Float64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Self::Float32 | Self::Float64)
    }

    /// The value in the first `size_bytes()` of `raw` (every PLY scalar fits an f64 exactly).
    fn decode(self, raw: &[u8], big_endian: bool) -> f64 {
        fn array<const N: usize>(raw: &[u8]) -> [u8; N] {
            let mut bytes = [0; N];
            bytes.copy_from_slice(&raw[..N]);
            bytes
        }
        macro_rules! decode {
            ($t:ty) => {{
                let bytes = array(raw);
                f64::from(if big_endian {
                    <$t>::from_be_bytes(bytes)
                } else {
                    <$t>::from_le_bytes(bytes)
                })
            }};
        }
        match self {
            Self::Int8 => decode!(i8),
            Self::Uint8 => decode!(u8),
            Self::Int16 => decode!(i16),
            Self::Uint16 => decode!(u16),
            Self::Int32 => decode!(i32),
            Self::Uint32 => decode!(u32),
            Self::Float32 => decode!(f32),
            Self::Float64 => decode!(f64),
        }
    }
}

impl fmt::Display for ScalarType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Int8 => "char",
            Self::Uint8 => "uchar",
            Self::Int16 => "short",
            Self::Uint16 => "ushort",
            Self::Int32 => "int",
            Self::Uint32 => "uint",
            Self::Float32 => "float",
            Self::Float64 => "double",
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PropertyType {
    Scalar(ScalarType),
    /// A length of type `count`, then that many values of type `item`.
    List {
        count: ScalarType,
        item: ScalarType,
    },
}

#[derive(Debug)]
struct Property {
    name: String,
    ty: PropertyType,
}

#[derive(Debug)]
struct Element {
    name: String,
    /// Declared number of entries: untrusted, so it bounds loops but never an allocation.
    count: usize,
    properties: Vec<Property>,
    /// Header line of the `element` statement.
    line: usize,
}

impl Element {
    /// Fewest bytes one binary entry can take.
    fn min_binary_size(&self) -> usize {
        self.properties
            .iter()
            .map(|p| match p.ty {
                PropertyType::Scalar(ty) => ty.size_bytes(),
                PropertyType::List { count, .. } => count.size_bytes(),
            })
            .sum()
    }

    /// Size of one binary entry when it has no list property.
    fn fixed_binary_size(&self) -> Option<usize> {
        self.properties
            .iter()
            .map(|p| match p.ty {
                PropertyType::Scalar(ty) => Some(ty.size_bytes()),
                PropertyType::List { .. } => None,
            })
            .sum()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Storage {
    Ascii,
    Binary { big_endian: bool },
}

#[derive(Debug)]
struct Header {
    storage: Storage,
    elements: Vec<Element>,
    /// Offset of the first byte after the `end_header` line.
    body_offset: usize,
    /// Line number of the first body line (for ascii bodies).
    body_first_line: usize,
    warnings: Vec<String>,
}

impl Header {
    fn parse(bytes: &[u8], file: &str) -> Result<Self, MeshIoError> {
        let bad = |line: usize, expected: &str, found: String| MeshIoError::BadHeader {
            file: file.to_owned(),
            at: Location::Line(line),
            expected: expected.to_owned(),
            found,
        };
        let found_or_end = |token: Option<&[u8]>| {
            token.map_or_else(|| "the end of the line".to_owned(), text::quote)
        };
        let mut lines = Lines::numbered_from(bytes, 1);
        match lines.next() {
            Some((_, line)) if line.trim_ascii_end() == b"ply" => {}
            Some((number, line)) => {
                return Err(bad(number, "the magic line `ply`", text::quote(line)));
            }
            None => return Err(bad(1, "the magic line `ply`", "an empty file".to_owned())),
        }
        let mut storage = None;
        let mut elements: Vec<Element> = Vec::new();
        let mut warnings = Vec::new();
        let end_line = loop {
            let Some((number, line)) = lines.next() else {
                return Err(bad(
                    lines.next_number(),
                    "`end_header`",
                    "the end of the file".to_owned(),
                ));
            };
            let mut words = text::tokens(line);
            let Some(keyword) = words.next() else {
                continue;
            };
            match keyword {
                b"comment" | b"obj_info" => {}
                b"format" => {
                    let encoding = words.next();
                    storage = Some(match encoding {
                        Some(b"ascii") => Storage::Ascii,
                        Some(b"binary_little_endian") => Storage::Binary { big_endian: false },
                        Some(b"binary_big_endian") => Storage::Binary { big_endian: true },
                        other => {
                            return Err(bad(
                                number,
                                "`ascii`, `binary_little_endian` or `binary_big_endian`",
                                found_or_end(other),
                            ));
                        }
                    });
                    if let Some(version) = words.next().filter(|v| *v != b"1.0") {
                        warnings.push(format!("PLY version {} read as 1.0", text::quote(version)));
                    }
                }
                b"element" => {
                    let name = words
                        .next()
                        .ok_or_else(|| bad(number, "an element name", found_or_end(None)))?;
                    let count_token = words.next();
                    let count = count_token
                        .and_then(text::parse_i64)
                        .and_then(|count| usize::try_from(count).ok())
                        .ok_or_else(|| {
                            bad(
                                number,
                                "a non-negative entry count",
                                found_or_end(count_token),
                            )
                        })?;
                    elements.push(Element {
                        name: String::from_utf8_lossy(name).into_owned(),
                        count,
                        properties: Vec::new(),
                        line: number,
                    });
                }
                b"property" => {
                    let Some(element) = elements.last_mut() else {
                        return Err(bad(
                            number,
                            "an `element` line before the first `property`",
                            text::quote(line),
                        ));
                    };
                    let scalar_type = |token: Option<&[u8]>, what: &str| {
                        token.and_then(ScalarType::from_name).ok_or_else(|| {
                            bad(
                                number,
                                &format!("{what}: char, uchar, short, ushort, int, uint, float, double or int8 … float64"),
                                found_or_end(token),
                            )
                        })
                    };
                    let first = words.next();
                    let ty = if first == Some(b"list") {
                        let count = scalar_type(words.next(), "the type of the list length")?;
                        if !count.is_integer() {
                            return Err(bad(
                                number,
                                "an integer type for the list length",
                                count.to_string(),
                            ));
                        }
                        PropertyType::List {
                            count,
                            item: scalar_type(words.next(), "the type of the list items")?,
                        }
                    } else {
                        PropertyType::Scalar(scalar_type(first, "a property type or `list`")?)
                    };
                    let name = words
                        .next()
                        .ok_or_else(|| bad(number, "a property name", found_or_end(None)))?;
                    element.properties.push(Property {
                        name: String::from_utf8_lossy(name).into_owned(),
                        ty,
                    });
                }
                b"end_header" => break number,
                _ => warnings.push(format!(
                    "ignored unknown PLY header line {number}: {}",
                    text::quote(line)
                )),
            }
        };
        let storage = storage.ok_or_else(|| {
            bad(
                end_line,
                "a `format` line before `end_header`",
                "none".to_owned(),
            )
        })?;
        Ok(Self {
            storage,
            elements,
            body_offset: lines.offset(),
            body_first_line: end_line + 1,
            warnings,
        })
    }
}

/// What the reader does with an element.
enum Role {
    /// The mesh's vertices; `axis[k]` is 0, 1, 2 for properties x, y, z.
    Vertex {
        axis: Vec<Option<usize>>,
    },
    /// The mesh's faces; `index_list` is the position of the vertex index list property.
    Face {
        index_list: usize,
    },
    Skip,
}

/// The role of each element; fails on a header this reader cannot use.
fn assign_roles(header: &Header, file: &str) -> Result<Vec<Role>, MeshIoError> {
    let mut roles = Vec::with_capacity(header.elements.len());
    for (k, element) in header.elements.iter().enumerate() {
        let role = match element.name.as_str() {
            "vertex" | "face" if header.elements[..k].iter().any(|e| e.name == element.name) => {
                Err((
                    format!("a single `{}` element", element.name),
                    "a second one".to_owned(),
                ))
            }
            "vertex" => vertex_role(element),
            "face" => face_role(element),
            _ => Ok(Role::Skip),
        };
        roles.push(role.map_err(|(expected, found)| MeshIoError::BadHeader {
            file: file.to_owned(),
            at: Location::Line(element.line),
            expected,
            found,
        })?);
    }
    Ok(roles)
}

/// The vertex element needs scalar `x`, `y` and `z`; fails with (expected, found).
fn vertex_role(element: &Element) -> Result<Role, (String, String)> {
    let axis: Vec<Option<usize>> = element
        .properties
        .iter()
        .map(|p| ["x", "y", "z"].iter().position(|a| *a == p.name))
        .collect();
    for (property, axis) in element.properties.iter().zip(&axis) {
        if axis.is_some() && matches!(property.ty, PropertyType::List { .. }) {
            return Err((
                format!("a scalar property `{}`", property.name),
                "a list".to_owned(),
            ));
        }
    }
    if (0..3).any(|a| !axis.contains(&Some(a))) {
        let names: Vec<&str> = element.properties.iter().map(|p| p.name.as_str()).collect();
        return Err((
            "properties `x`, `y` and `z` in element `vertex`".to_owned(),
            format!("properties {names:?}"),
        ));
    }
    Ok(Role::Vertex { axis })
}

/// The face element needs a `vertex_indices` (or `vertex_index`) list; fails with
/// (expected, found).
fn face_role(element: &Element) -> Result<Role, (String, String)> {
    let list = element
        .properties
        .iter()
        .position(|p| p.name == "vertex_indices" || p.name == "vertex_index");
    match list.map(|k| (k, element.properties[k].ty)) {
        Some((index_list, PropertyType::List { .. })) => Ok(Role::Face { index_list }),
        Some((_, PropertyType::Scalar(ty))) => Err((
            "`vertex_indices` to be a list property".to_owned(),
            format!("a scalar {ty}"),
        )),
        None => Err((
            "a list property `vertex_indices` (or `vertex_index`) in element `face`".to_owned(),
            "none".to_owned(),
        )),
    }
}

/// The current entry of a body reader, for error locations.
#[derive(Default)]
struct Entry {
    element: String,
    index: usize,
    /// Where the entry starts: a line (ascii) or a byte offset (binary).
    start: usize,
}

impl Entry {
    /// Moves to entry `index` of `element`, starting at `start`; the name's buffer is reused
    /// while the element stays the same.
    fn begin(&mut self, element: &Element, index: usize, start: usize) {
        if self.element != element.name {
            self.element.clone_from(&element.name);
        }
        self.index = index;
        self.start = start;
    }
}

/// Reads the values of a PLY body, ascii or binary, entry by entry.
trait Body {
    fn file(&self) -> &str;
    /// Starts entry `index` of `element`.
    fn begin_entry(&mut self, element: &Element, index: usize) -> Result<(), MeshIoError>;
    /// The next value, of type `ty`, of property `property`.
    fn scalar(&mut self, ty: ScalarType, property: &str) -> Result<f64, MeshIoError>;
    /// Fails if the entry holds more than its properties (ascii only: binary cannot tell).
    fn end_entry(&mut self) -> Result<(), MeshIoError>;
    /// Where the current entry starts.
    fn location(&self) -> Location;
    /// The most entries of `element` the unread data can hold: bounds pre-allocation.
    fn max_entries(&self, element: &Element) -> usize;
    /// A warning if data follows the last element.
    fn trailing_data(&mut self) -> Option<String>;

    /// A list's length, read with its count type.
    fn list_len(&mut self, count: ScalarType, property: &str) -> Result<usize, MeshIoError> {
        let value = self.scalar(count, property)?;
        if value >= 0.0 && value.fract() == 0.0 && value <= usize::MAX as f64 {
            Ok(value as usize)
        } else {
            Err(self.parse_error(
                format!("a list length for property `{property}`"),
                value.to_string(),
            ))
        }
    }

    fn skip_list(
        &mut self,
        count: ScalarType,
        item: ScalarType,
        property: &str,
    ) -> Result<(), MeshIoError> {
        for _ in 0..self.list_len(count, property)? {
            self.scalar(item, property)?;
        }
        Ok(())
    }

    fn skip_element(&mut self, element: &Element) -> Result<(), MeshIoError> {
        if element.properties.is_empty() {
            // Nothing to read, however many entries are declared.
            return Ok(());
        }
        for index in 0..element.count {
            self.begin_entry(element, index)?;
            for property in &element.properties {
                self.skip_property(property)?;
            }
            self.end_entry()?;
        }
        Ok(())
    }

    fn skip_property(&mut self, property: &Property) -> Result<(), MeshIoError> {
        match property.ty {
            PropertyType::Scalar(ty) => self.scalar(ty, &property.name).map(drop),
            PropertyType::List { count, item } => self.skip_list(count, item, &property.name),
        }
    }

    fn parse_error(&self, expected: String, found: String) -> MeshIoError {
        MeshIoError::Parse {
            file: self.file().to_owned(),
            at: self.location(),
            expected,
            found,
        }
    }
}

/// An ascii body: one entry a line, values separated by whitespace.
struct AsciiBody<'a> {
    file: &'a str,
    lines: Lines<'a>,
    /// The unread part of the current entry's line.
    rest_of_line: &'a [u8],
    entry: Entry,
}

impl<'a> AsciiBody<'a> {
    fn new(file: &'a str, body: &'a [u8], first_line: usize) -> Self {
        Self {
            file,
            lines: Lines::numbered_from(body, first_line),
            rest_of_line: &[],
            entry: Entry::default(),
        }
    }
}

impl Body for AsciiBody<'_> {
    fn file(&self) -> &str {
        self.file
    }

    fn begin_entry(&mut self, element: &Element, index: usize) -> Result<(), MeshIoError> {
        self.entry.begin(element, index, self.lines.next_number());
        loop {
            let Some((number, line)) = self.lines.next() else {
                self.entry.start = self.lines.next_number();
                return Err(MeshIoError::Truncated {
                    file: self.file.to_owned(),
                    at: self.location(),
                    expected: format!(
                        "{} `{}` entries, one a line, but the file ends",
                        element.count, element.name
                    ),
                });
            };
            if !text::is_blank(line) {
                self.entry.start = number;
                self.rest_of_line = line;
                return Ok(());
            }
        }
    }

    fn scalar(&mut self, ty: ScalarType, property: &str) -> Result<f64, MeshIoError> {
        let Some(token) = text::next_token(&mut self.rest_of_line) else {
            return Err(self.parse_error(
                format!("a value for property `{property}`"),
                "the end of the line".to_owned(),
            ));
        };
        text::parse_f64(token).ok_or_else(|| {
            self.parse_error(
                format!("a number ({ty}) for property `{property}`"),
                text::quote(token),
            )
        })
    }

    fn end_entry(&mut self) -> Result<(), MeshIoError> {
        match text::next_token(&mut self.rest_of_line) {
            None => Ok(()),
            Some(extra) => Err(self.parse_error(
                format!(
                    "the end of the line after the properties of `{}`",
                    self.entry.element
                ),
                format!("more values, from {}", text::quote(extra)),
            )),
        }
    }

    fn location(&self) -> Location {
        Location::ElementAtLine {
            element: self.entry.element.clone(),
            index: self.entry.index,
            line: self.entry.start,
        }
    }

    fn max_entries(&self, element: &Element) -> usize {
        // Each value takes a character and a separator at least.
        self.lines.remaining_bytes() / (2 * element.properties.len()).max(1) + 1
    }

    fn trailing_data(&mut self) -> Option<String> {
        let (number, _) = self
            .lines
            .by_ref()
            .find(|(_, line)| !text::is_blank(line))?;
        Some(format!(
            "ignored data after the last element, from line {number}"
        ))
    }
}

/// A binary body: values packed back to back in the header's byte order.
struct BinaryBody<'a> {
    file: &'a str,
    /// The whole file, so that offsets in messages count from its start.
    bytes: &'a [u8],
    offset: usize,
    big_endian: bool,
    entry: Entry,
}

impl BinaryBody<'_> {
    fn remaining_bytes(&self) -> usize {
        self.bytes.len().saturating_sub(self.offset)
    }

    fn truncated(&self, expected: String) -> MeshIoError {
        MeshIoError::Truncated {
            file: self.file.to_owned(),
            at: self.location(),
            expected,
        }
    }

    /// Skips `len` bytes of the current entry.
    fn skip_bytes(
        &mut self,
        len: Option<usize>,
        what: impl FnOnce() -> String,
    ) -> Result<(), MeshIoError> {
        match len.filter(|&len| len <= self.remaining_bytes()) {
            Some(len) => {
                self.offset += len;
                Ok(())
            }
            None => Err(self.truncated(format!(
                "{}; the file ends at byte {}",
                what(),
                self.bytes.len()
            ))),
        }
    }
}

impl Body for BinaryBody<'_> {
    fn file(&self) -> &str {
        self.file
    }

    fn begin_entry(&mut self, element: &Element, index: usize) -> Result<(), MeshIoError> {
        self.entry.begin(element, index, self.offset);
        Ok(())
    }

    fn scalar(&mut self, ty: ScalarType, property: &str) -> Result<f64, MeshIoError> {
        let size = ty.size_bytes();
        let Some(raw) = self
            .bytes
            .get(self.offset..)
            .and_then(|rest| rest.get(..size))
        else {
            return Err(self.truncated(format!(
                "{size} bytes ({ty}) of property `{property}` at byte {}; the file ends at byte {}",
                self.offset,
                self.bytes.len()
            )));
        };
        self.offset += size;
        Ok(ty.decode(raw, self.big_endian))
    }

    fn end_entry(&mut self) -> Result<(), MeshIoError> {
        Ok(())
    }

    fn location(&self) -> Location {
        Location::ElementAtByte {
            element: self.entry.element.clone(),
            index: self.entry.index,
            byte: self.entry.start as u64,
        }
    }

    fn max_entries(&self, element: &Element) -> usize {
        self.remaining_bytes() / element.min_binary_size().max(1)
    }

    fn trailing_data(&mut self) -> Option<String> {
        let extra = self.remaining_bytes();
        (extra > 0).then(|| format!("ignored {extra} bytes after the last element"))
    }

    fn skip_list(
        &mut self,
        count: ScalarType,
        item: ScalarType,
        property: &str,
    ) -> Result<(), MeshIoError> {
        let len = self.list_len(count, property)?;
        self.skip_bytes(len.checked_mul(item.size_bytes()), || {
            format!("{len} list items ({item}) of property `{property}`")
        })
    }

    fn skip_element(&mut self, element: &Element) -> Result<(), MeshIoError> {
        let Some(entry_size) = element.fixed_binary_size() else {
            // Lists make entries differ in size: walk them. Each step reads at least a list
            // length, so a huge declared count ends at the end of the file.
            for index in 0..element.count {
                self.begin_entry(element, index)?;
                for property in &element.properties {
                    self.skip_property(property)?;
                }
            }
            return Ok(());
        };
        let whole_entries = self.remaining_bytes() / entry_size.max(1);
        if entry_size > 0 && element.count > whole_entries {
            // Report the first entry that does not fit.
            self.begin_entry(element, whole_entries)?;
            self.entry.start = self.offset + whole_entries * entry_size;
            return Err(self.truncated(format!(
                "{} `{}` entries of {entry_size} bytes; the file ends at byte {}",
                element.count,
                element.name,
                self.bytes.len()
            )));
        }
        self.offset += entry_size * element.count;
        Ok(())
    }
}

/// Turns a PLY body into a mesh, whatever the encoding.
struct MeshReader<'h> {
    header: &'h Header,
    roles: &'h [Role],
    metres_per_unit: f64,
}

impl MeshReader<'_> {
    fn read(&self, body: &mut impl Body) -> Result<ParsedMesh, MeshIoError> {
        let vertex_count = self
            .header
            .elements
            .iter()
            .zip(self.roles)
            .find_map(|(element, role)| {
                matches!(role, Role::Vertex { .. }).then_some(element.count)
            })
            .unwrap_or(0);
        let mut mesh = TriMesh::default();
        let mut warnings = Vec::new();
        let mut short_faces = 0;
        for (element, role) in self.header.elements.iter().zip(self.roles) {
            match role {
                Role::Vertex { axis } => mesh.vertices = self.read_vertices(body, element, axis)?,
                Role::Face { index_list } => {
                    short_faces += read_faces(
                        body,
                        element,
                        *index_list,
                        vertex_count,
                        &mut mesh.triangles,
                    )?;
                }
                Role::Skip => {
                    body.skip_element(element)?;
                    if element.count > 0 {
                        warnings.push(format!(
                            "ignored PLY element `{}` ({} entries)",
                            element.name, element.count
                        ));
                    }
                }
            }
        }
        if short_faces > 0 {
            warnings.push(format!(
                "ignored {short_faces} faces with fewer than 3 vertices"
            ));
        }
        warnings.extend(body.trailing_data());
        Ok(ParsedMesh {
            mesh,
            warnings,
            triangle_soup: false,
        })
    }

    fn read_vertices(
        &self,
        body: &mut impl Body,
        element: &Element,
        axis: &[Option<usize>],
    ) -> Result<Vec<Point3<f32>>, MeshIoError> {
        let mut vertices = Vec::with_capacity(element.count.min(body.max_entries(element)));
        for index in 0..element.count {
            body.begin_entry(element, index)?;
            let mut xyz = [0.0f64; 3];
            for (property, axis) in element.properties.iter().zip(axis) {
                match (property.ty, axis) {
                    (PropertyType::Scalar(ty), Some(axis)) => {
                        xyz[*axis] = body.scalar(ty, &property.name)?
                    }
                    _ => body.skip_property(property)?,
                }
            }
            body.end_entry()?;
            vertices.push(Point3::from(xyz.map(|c| (c * self.metres_per_unit) as f32)));
        }
        Ok(vertices)
    }
}

/// Reads the faces into `triangles`, fan-triangulating polygons; every index is checked
/// against the declared `vertex_count` (vertices may come after the faces). Returns the number
/// of faces with fewer than three corners, which are skipped.
fn read_faces(
    body: &mut impl Body,
    element: &Element,
    index_list: usize,
    vertex_count: usize,
    triangles: &mut Vec<[u32; 3]>,
) -> Result<usize, MeshIoError> {
    triangles.reserve(element.count.min(body.max_entries(element)));
    let mut polygon: Vec<u32> = Vec::new();
    let mut short_faces = 0;
    for index in 0..element.count {
        body.begin_entry(element, index)?;
        polygon.clear();
        for (k, property) in element.properties.iter().enumerate() {
            let PropertyType::List { count, item } = property.ty else {
                body.skip_property(property)?;
                continue;
            };
            if k != index_list {
                body.skip_list(count, item, &property.name)?;
                continue;
            }
            // Grows only as values are actually read: the declared length is untrusted.
            for _ in 0..body.list_len(count, &property.name)? {
                let value = body.scalar(item, &property.name)?;
                if !(value.is_finite() && value.fract() == 0.0) {
                    return Err(
                        body.parse_error("an integer vertex index".to_owned(), value.to_string())
                    );
                }
                let vertex = (value >= 0.0 && value < vertex_count as f64)
                    .then(|| u32::try_from(value as u64).ok())
                    .flatten()
                    .ok_or_else(|| MeshIoError::IndexOutOfRange {
                        file: body.file().to_owned(),
                        at: body.location(),
                        index: value as i64,
                        vertex_count,
                    })?;
                polygon.push(vertex);
            }
        }
        body.end_entry()?;
        match polygon.as_slice() {
            [first, rest @ ..] if rest.len() >= 2 => {
                triangles.extend(rest.windows(2).map(|pair| [*first, pair[0], pair[1]]));
            }
            _ => short_faces += 1,
        }
    }
    Ok(short_faces)
}

#[cfg(test)]
mod tests {
    use super::super::test_meshes::{
        BOX_VOLUME_MM3, assert_same_vertices, bop_like_ply, box_mesh_mm, box_quads_mm, mm_to_m,
    };
    use super::super::{LoadedMesh, MeshFormat, read_mesh_from_bytes, write_ply_to_vec};
    use super::*;
    use crate::mesh::MeshError;

    fn read_ply(bytes: &[u8], unit: LengthUnit) -> Result<LoadedMesh, MeshIoError> {
        read_mesh_from_bytes(bytes, MeshFormat::Ply, unit, "test.ply")
    }

    fn assert_is_the_box_in_metres(loaded: &LoadedMesh) {
        let expected = mm_to_m(&box_mesh_mm());
        assert_same_vertices(&loaded.mesh.vertices, &expected.vertices);
        assert_eq!(loaded.mesh.triangles.len(), 12);
        assert!(loaded.report.is_watertight(), "{:?}", loaded.report);
        let volume_m3 = BOX_VOLUME_MM3 * 1e-9;
        assert!(
            (loaded.report.signed_volume_m3 / volume_m3 - 1.0).abs() < 1e-6,
            "{}",
            loaded.report.signed_volume_m3
        );
    }

    #[test]
    fn round_trips_in_both_encodings_and_units() {
        let mesh = mm_to_m(&box_mesh_mm());
        for encoding in [PlyEncoding::BinaryLittleEndian, PlyEncoding::Ascii] {
            for unit in [LengthUnit::Millimetre, LengthUnit::Metre] {
                let bytes = write_ply_to_vec(&mesh, unit, encoding);
                let loaded = read_ply(&bytes, unit).unwrap();
                assert_same_vertices(&loaded.mesh.vertices, &mesh.vertices);
                assert_eq!(loaded.mesh.triangles, mesh.triangles, "{encoding:?} {unit}");
                assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
                assert_is_the_box_in_metres(&loaded);
            }
        }
        // Binary: the header, then 12 bytes a vertex and 13 a triangle.
        let bytes = write_ply_to_vec(
            &mesh,
            LengthUnit::Millimetre,
            PlyEncoding::BinaryLittleEndian,
        );
        let header_len = Header::parse(&bytes, "x").unwrap().body_offset;
        assert_eq!(bytes.len(), header_len + 8 * 12 + 12 * 13);
        // A millimetre file read as metres is a thousand times too large.
        let as_metres = read_ply(&bytes, LengthUnit::Metre).unwrap();
        let extent = as_metres.report.aabb_max - as_metres.report.aabb_min;
        assert!((extent.x - 40.0).abs() < 1e-4, "{extent}");
    }

    #[test]
    fn ascii_output_is_plain_and_in_the_requested_unit() {
        let bytes = write_ply_to_vec(
            &mm_to_m(&box_mesh_mm()),
            LengthUnit::Millimetre,
            PlyEncoding::Ascii,
        );
        let text = String::from_utf8(bytes).unwrap();
        assert!(text.starts_with("ply\nformat ascii 1.0\n"));
        assert!(text.contains("\nelement vertex 8\n") && text.contains("\nelement face 12\n"));
        assert!(text.contains("\n-10 -20 5\n"), "{text}");
        assert!(text.ends_with("\n3 1 3 7\n3 1 7 5\n"), "{text}");
    }

    #[test]
    fn reads_bop_models_in_either_byte_order() {
        for little_endian in [true, false] {
            let loaded = read_ply(
                &bop_like_ply(&box_mesh_mm(), little_endian),
                LengthUnit::Millimetre,
            )
            .unwrap();
            assert_is_the_box_in_metres(&loaded);
            assert!(loaded.warnings.is_empty(), "{:?}", loaded.warnings);
        }
    }

    /// A value of a test file: a scalar or a list.
    enum Value {
        S(f64),
        L(Vec<f64>),
    }
    use Value::{L, S};

    /// A test element: name, property declarations as the header writes them, rows.
    type TestElement<'a> = (&'a str, &'a [&'a str], Vec<Vec<Value>>);

    /// Writes a PLY file from a description, encoding each value by its declared type.
    fn build_ply(storage: Storage, elements: &[TestElement]) -> Vec<u8> {
        let format = match storage {
            Storage::Ascii => "ascii",
            Storage::Binary { big_endian: false } => "binary_little_endian",
            Storage::Binary { big_endian: true } => "binary_big_endian",
        };
        let mut header =
            format!("ply\r\nformat {format} 1.0\r\ncomment every type, in odd order\r\n");
        let mut body = Vec::new();
        for (name, declarations, rows) in elements {
            header += &format!("element {name} {}\r\n", rows.len());
            for declaration in *declarations {
                header += &format!("property {declaration}\r\n");
            }
            for row in rows {
                let mut values: Vec<(&[u8], f64)> = Vec::new();
                for (declaration, value) in declarations.iter().zip(row) {
                    let words: Vec<&[u8]> = declaration.split(' ').map(str::as_bytes).collect();
                    match value {
                        S(v) => values.push((words[0], *v)),
                        L(items) => {
                            values.push((words[1], items.len() as f64));
                            values.extend(items.iter().map(|v| (words[2], *v)));
                        }
                    }
                }
                let big_endian = storage == Storage::Binary { big_endian: true };
                for (ty, v) in values {
                    let ty = ScalarType::from_name(ty).unwrap();
                    match storage {
                        Storage::Ascii => body.extend_from_slice(format!("{v} ").as_bytes()),
                        Storage::Binary { .. } => {
                            let mut le: Vec<u8> = match ty {
                                ScalarType::Int8 => (v as i8).to_le_bytes().to_vec(),
                                ScalarType::Uint8 => (v as u8).to_le_bytes().to_vec(),
                                ScalarType::Int16 => (v as i16).to_le_bytes().to_vec(),
                                ScalarType::Uint16 => (v as u16).to_le_bytes().to_vec(),
                                ScalarType::Int32 => (v as i32).to_le_bytes().to_vec(),
                                ScalarType::Uint32 => (v as u32).to_le_bytes().to_vec(),
                                ScalarType::Float32 => (v as f32).to_le_bytes().to_vec(),
                                ScalarType::Float64 => v.to_le_bytes().to_vec(),
                            };
                            if big_endian {
                                le.reverse();
                            }
                            body.extend_from_slice(&le);
                        }
                    }
                }
                if storage == Storage::Ascii {
                    body.extend_from_slice(b"\r\n");
                }
            }
        }
        header += "end_header\r\n";
        let mut bytes = header.into_bytes();
        bytes.extend_from_slice(&body);
        bytes
    }

    /// The box as quads, with extra elements and properties of every type around the ones
    /// that matter, faces before vertices.
    fn box_with_extras() -> Vec<TestElement<'static>> {
        let (vertices, quads) = box_quads_mm();
        vec![
            (
                "material",
                &["int8 shininess", "list uint16 uint32 ids", "float64 gloss"],
                vec![
                    vec![S(-3.0), L(vec![1.0, 70000.0]), S(0.25)],
                    vec![S(4.0), L(vec![]), S(0.5)],
                ],
            ),
            (
                "face",
                &[
                    "short group",
                    "list uint8 int32 vertex_index",
                    "list ushort char flags",
                ],
                quads
                    .iter()
                    .map(|q| {
                        vec![
                            S(-7.0),
                            L(q.iter().map(|&v| f64::from(v)).collect()),
                            L(vec![-1.0, 2.0]),
                        ]
                    })
                    .collect(),
            ),
            (
                "vertex",
                &[
                    "uchar red",
                    "double x",
                    "list uchar float uv",
                    "float32 y",
                    "int z",
                    "uint16 id",
                ],
                vertices
                    .iter()
                    .enumerate()
                    .map(|(i, p)| {
                        let c = p.map(f64::from);
                        vec![
                            S(200.0),
                            S(c.x),
                            L(vec![0.5, 0.25]),
                            S(c.y),
                            S(c.z),
                            S(i as f64),
                        ]
                    })
                    .collect(),
            ),
            (
                "edge",
                &["int vertex1", "uint vertex2"],
                vec![vec![S(0.0), S(1.0)], vec![S(1.0), S(3.0)]],
            ),
        ]
    }

    const EVERY_STORAGE: [Storage; 3] = [
        Storage::Ascii,
        Storage::Binary { big_endian: false },
        Storage::Binary { big_endian: true },
    ];

    #[test]
    fn skips_unknown_elements_and_properties_of_every_type_in_any_order() {
        for storage in EVERY_STORAGE {
            let bytes = build_ply(storage, &box_with_extras());
            let loaded = read_ply(&bytes, LengthUnit::Millimetre)
                .unwrap_or_else(|e| panic!("{storage:?}: {e}"));
            // Six quads, fan-triangulated.
            assert_is_the_box_in_metres(&loaded);
            assert_eq!(
                loaded.warnings,
                [
                    "ignored PLY element `material` (2 entries)",
                    "ignored PLY element `edge` (2 entries)"
                ]
            );
        }
    }

    #[test]
    fn truncated_binary_names_the_entry_and_byte() {
        let bytes = bop_like_ply(&box_mesh_mm(), true);
        let body_offset = Header::parse(&bytes, "x").unwrap().body_offset;
        // A BOP vertex is 6 floats and 4 colour bytes.
        let vertex_bytes = 28;
        let cut = body_offset + 3 * vertex_bytes + 5;
        let err = read_ply(&bytes[..cut], LengthUnit::Millimetre).unwrap_err();
        match &err {
            MeshIoError::Truncated { file, at, .. } => {
                assert_eq!(file, "test.ply");
                let byte = (body_offset + 3 * vertex_bytes) as u64;
                assert_eq!(
                    at,
                    &Location::ElementAtByte {
                        element: "vertex".into(),
                        index: 3,
                        byte
                    }
                );
            }
            other => panic!("{other:?}"),
        }
        assert!(
            err.to_string()
                .starts_with("test.ply: the data ends early, at vertex 3 (byte "),
            "{err}"
        );
        // Inside the faces: 13 index bytes and a 25-byte texcoord list each.
        let faces_start = body_offset + 8 * vertex_bytes;
        let err =
            read_ply(&bytes[..faces_start + 2 * 38 + 20], LengthUnit::Millimetre).unwrap_err();
        assert!(
            matches!(&err, MeshIoError::Truncated { at: Location::ElementAtByte { element, index: 2, .. }, .. } if element == "face"),
            "{err:?}"
        );
        // Ascii: the data stops after two vertices.
        let ascii = write_ply_to_vec(
            &mm_to_m(&box_mesh_mm()),
            LengthUnit::Metre,
            PlyEncoding::Ascii,
        );
        let text = String::from_utf8(ascii).unwrap();
        let cut = text.find("end_header\n").unwrap() + "end_header\n".len();
        let two_vertices: String = text[cut..]
            .lines()
            .take(2)
            .map(|l| format!("{l}\n"))
            .collect();
        let err = read_ply(
            format!("{}{two_vertices}", &text[..cut]).as_bytes(),
            LengthUnit::Metre,
        )
        .unwrap_err();
        assert!(
            matches!(
                &err,
                MeshIoError::Truncated {
                    at: Location::ElementAtLine {
                        index: 2,
                        line: 13,
                        ..
                    },
                    ..
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn bad_headers_are_located() {
        let vertex = "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n";
        let face = "element face 1\nproperty list uchar int vertex_indices\n";
        let cases: Vec<(String, usize, &str)> = vec![
            ("".to_owned(), 1, "the magic line `ply`"),
            ("PLY\nformat ascii 1.0\n".to_owned(), 1, "the magic line `ply`"),
            (format!("ply\nformat ascii 1.0\n{vertex}{face}"), 9, "`end_header`"),
            (format!("ply\n{vertex}{face}end_header\n"), 8, "a `format` line"),
            ("ply\nformat binary_middle_endian 1.0\nend_header\n".to_owned(), 2, "`ascii`"),
            ("ply\nformat ascii 1.0\nproperty float x\nend_header\n".to_owned(), 3, "an `element` line"),
            ("ply\nformat ascii 1.0\nelement vertex -3\nend_header\n".to_owned(), 3, "a non-negative entry count"),
            ("ply\nformat ascii 1.0\nelement vertex 3\nproperty flaot x\n".to_owned(), 4, "a property type"),
            (
                "ply\nformat ascii 1.0\nelement face 3\nproperty list float int vertex_indices\n".to_owned(),
                4,
                "an integer type for the list length",
            ),
            (
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nend_header\n".to_owned(),
                3,
                "properties `x`, `y` and `z`",
            ),
            (
                format!("ply\nformat ascii 1.0\n{vertex}element face 1\nproperty list uchar int corners\nend_header\n"),
                7,
                "a list property `vertex_indices`",
            ),
            (format!("ply\nformat ascii 1.0\n{vertex}{face}{vertex}end_header\n"), 9, "a single `vertex` element"),
        ];
        for (header, line, expected_start) in cases {
            let err = read_ply(header.as_bytes(), LengthUnit::Metre).unwrap_err();
            match &err {
                MeshIoError::BadHeader {
                    file, at, expected, ..
                } => {
                    assert_eq!(file, "test.ply");
                    assert_eq!(at, &Location::Line(line), "{header:?}: {err}");
                    assert!(expected.starts_with(expected_start), "{header:?}: {err}");
                }
                other => panic!("{header:?}: {other:?}"),
            }
            assert!(
                err.to_string()
                    .starts_with("test.ply: bad PLY header at line"),
                "{err}"
            );
        }
    }

    fn ascii_tetrahedron(faces: &str) -> Vec<u8> {
        format!(
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n\
             0 0 0\n1 0 0\n0 1 0\n0 0 1\n{faces}",
            faces.lines().count()
        )
        .into_bytes()
    }

    #[test]
    fn tetrahedron_reads_and_faces_are_checked() {
        let closed = "3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
        let loaded = read_ply(&ascii_tetrahedron(closed), LengthUnit::Metre).unwrap();
        assert!(loaded.report.is_watertight());
        assert!((loaded.report.signed_volume_m3 - 1.0 / 6.0).abs() < 1e-7);

        let err =
            read_ply(&ascii_tetrahedron("3 0 2 1\n3 0 1 7\n"), LengthUnit::Metre).unwrap_err();
        match &err {
            MeshIoError::IndexOutOfRange {
                at,
                index: 7,
                vertex_count: 4,
                ..
            } => {
                assert_eq!(
                    at,
                    &Location::ElementAtLine {
                        element: "face".into(),
                        index: 1,
                        line: 15
                    }
                );
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            err.to_string(),
            "test.ply: at face 1 (line 15): vertex index 7 is out of range: the file has 4 vertices"
        );
        let err = read_ply(&ascii_tetrahedron("3 0 -1 1\n"), LengthUnit::Metre).unwrap_err();
        assert!(
            matches!(err, MeshIoError::IndexOutOfRange { index: -1, .. }),
            "{err:?}"
        );
        let err = read_ply(&ascii_tetrahedron("3 0 1.5 1\n"), LengthUnit::Metre).unwrap_err();
        assert!(matches!(err, MeshIoError::Parse { .. }), "{err:?}");
        // Faces with fewer than three corners are skipped with a warning.
        let loaded =
            read_ply(&ascii_tetrahedron("3 0 2 1\n2 0 1\n0\n"), LengthUnit::Metre).unwrap();
        assert_eq!(loaded.mesh.triangles.len(), 1);
        assert!(
            loaded
                .warnings
                .contains(&"ignored 2 faces with fewer than 3 vertices".to_owned())
        );
    }

    #[test]
    fn wrong_value_counts_in_ascii_are_located() {
        let cases = [
            (
                "0 0 0\n1 0\n0 1 0\n0 0 1\n3 0 1 2\n",
                "vertex",
                1,
                11,
                "a value for property `z`",
            ),
            (
                "0 0 0\n1 0 0 0\n0 1 0\n0 0 1\n3 0 1 2\n",
                "vertex",
                1,
                11,
                "the end of the line",
            ),
            (
                "0 0 0\n1 0 0\n0 1 0\n0 0 1\n4 0 1 2\n",
                "face",
                0,
                14,
                "a value for property `vertex_indices`",
            ),
            (
                "0 0 0\n1 0 0\n0 x 0\n0 0 1\n3 0 1 2\n",
                "vertex",
                2,
                12,
                "a number (float) for property `y`",
            ),
            (
                "0 0 0\n1 0 0\n0 1 0\n0 0 1\n-3 0 1 2\n",
                "face",
                0,
                14,
                "a list length",
            ),
        ];
        for (body, element, index, line, expected_start) in cases {
            let bytes = format!(
                "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
                 element face 1\nproperty list uchar int vertex_indices\nend_header\n{body}"
            );
            let err = read_ply(bytes.as_bytes(), LengthUnit::Metre).unwrap_err();
            match &err {
                MeshIoError::Parse { at, expected, .. } => {
                    assert_eq!(
                        at,
                        &Location::ElementAtLine {
                            element: element.into(),
                            index,
                            line
                        },
                        "{err}"
                    );
                    assert!(expected.starts_with(expected_start), "{err}");
                }
                other => panic!("{body:?}: {other:?}"),
            }
        }
    }

    #[test]
    fn huge_declared_counts_fail_fast() {
        let vertices = "property float x\nproperty float y\nproperty float z\n";
        for format in ["ascii", "binary_little_endian"] {
            let bytes = format!(
                "ply\nformat {format} 1.0\nelement vertex 4000000000000000\n{vertices}\
                 element face 4000000000000000\nproperty list uint int vertex_indices\nend_header\n0 0 0\n"
            );
            let err = read_ply(bytes.as_bytes(), LengthUnit::Metre).unwrap_err();
            assert!(
                matches!(err, MeshIoError::Truncated { .. }),
                "{format}: {err:?}"
            );
        }
        // A face list declaring four billion corners, and an element of empty entries.
        let mut bytes = format!(
            "ply\nformat binary_little_endian 1.0\nelement nothing 4000000000000000\n\
             element vertex 1\n{vertices}element face 1\nproperty list uint int vertex_indices\nend_header\n"
        )
        .into_bytes();
        let face_start = bytes.len() + 12;
        bytes.extend_from_slice(&[0; 12]);
        bytes.extend_from_slice(&u32::MAX.to_le_bytes());
        bytes.extend_from_slice(&[0; 8]);
        let err = read_ply(&bytes, LengthUnit::Metre).unwrap_err();
        match err {
            MeshIoError::Truncated {
                at:
                    Location::ElementAtByte {
                        element,
                        index: 0,
                        byte,
                    },
                ..
            } => {
                assert_eq!((element.as_str(), byte), ("face", face_start as u64));
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn non_finite_vertices_are_invalid() {
        let mut mesh = mm_to_m(&box_mesh_mm());
        mesh.vertices[5].z = f32::NAN;
        let bytes = write_ply_to_vec(&mesh, LengthUnit::Metre, PlyEncoding::BinaryLittleEndian);
        let err = read_ply(&bytes, LengthUnit::Metre).unwrap_err();
        assert!(
            matches!(
                err,
                MeshIoError::InvalidMesh {
                    source: MeshError::NonFiniteVertex { index: 5, .. },
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("test.ply"));
    }

    #[test]
    fn trailing_data_is_a_warning() {
        let mut bytes = write_ply_to_vec(
            &mm_to_m(&box_mesh_mm()),
            LengthUnit::Metre,
            PlyEncoding::BinaryLittleEndian,
        );
        bytes.extend_from_slice(b"junk");
        let loaded = read_ply(&bytes, LengthUnit::Metre).unwrap();
        assert_eq!(loaded.warnings, ["ignored 4 bytes after the last element"]);
    }
}
