//! The generic container of every model file that `supine-core` reads (body model, joint forest, shape forest, ...).
//!
//! A model file is a 32-byte header, a table of typed sections and the section data, all little-endian. It is
//! validated once, in [`ModelFile::parse`] (sizes, magic, versions, CRC-32C, section bounds, alignment, element
//! types), and then hands out borrowed, zero-copy [`LeSlice`] views of its sections: no allocation, no copy, and no
//! `unsafe` (elements are decoded with `from_le_bytes`, which compiles to a plain load on little-endian targets).
//! A bad file gives a [`ModelFileError`] that names what is wrong; parsing never panics, whatever the bytes.
//!
//! ```text
//! offset size  field
//!  0      8    magic  b"SUPMODEL"
//!  8      2    container version (u16, = CONTAINER_VERSION)
//! 10      2    section count (u16)
//! 12      4    kind tag (4 ASCII bytes, e.g. b"BODY")
//! 16      2    kind format version (u16; each kind defines its own)
//! 18      2    reserved, 0
//! 20      4    total file length in bytes (u32)
//! 24      4    CRC-32C over bytes [0, 24) followed by [28, total)   (everything but this field)
//! 28      4    reserved, 0
//! 32   16·n    section table, n entries:
//!                tag [u8; 4] | element type u8 | 3 bytes reserved 0 | offset u32 | element count u32
//! ...          section data; every section starts at a multiple of SECTION_ALIGN from the file start
//! ```
//!
//! The writer ([`encoded_len`], [`fn@write`]) is here too (it needs no allocation either: the caller provides the
//! output buffer), so that every file kind is produced by the same code that validates it.
//! Cost: `parse` is one CRC-32C pass over the file (about 1 ns/byte) plus O(sections); views cost nothing per use.

use core::fmt;
use core::marker::PhantomData;

use crate::crc::crc32c_update;

/// The 8 magic bytes at the start of every model file.
pub const MAGIC: [u8; 8] = *b"SUPMODEL";
/// Version of the container layout described in the module docs.
pub const CONTAINER_VERSION: u16 = 1;
/// Size of the fixed header in bytes.
pub const HEADER_LEN: usize = 32;
/// Size of one section-table entry in bytes.
pub const SECTION_ENTRY_LEN: usize = 16;
/// Every section's data starts at a multiple of this many bytes (enough for any element type, and for SIMD loads).
pub const SECTION_ALIGN: usize = 16;
/// Most sections a file may have (keeps validation O(1)-bounded and duplicate checks cheap).
pub const MAX_SECTIONS: usize = 64;

/// A 4-byte ASCII tag naming a file kind or a section.
pub type Tag = [u8; 4];

/// The element type of a section, stored as one byte in the section table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ElemType {
    /// Unsigned byte (also used for UTF-8 text).
    U8 = 1,
    /// Signed byte.
    I8 = 2,
    /// Little-endian u16.
    U16 = 3,
    /// Little-endian i16.
    I16 = 4,
    /// Little-endian u32.
    U32 = 5,
    /// Little-endian i32.
    I32 = 6,
    /// Little-endian IEEE-754 binary32.
    F32 = 7,
}

impl ElemType {
    /// Size of one element in bytes.
    pub const fn size(self) -> usize {
        match self {
            ElemType::U8 | ElemType::I8 => 1,
            ElemType::U16 | ElemType::I16 => 2,
            ElemType::U32 | ElemType::I32 | ElemType::F32 => 4,
        }
    }

    /// Decode the table byte; `None` for an unknown code.
    pub const fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => ElemType::U8,
            2 => ElemType::I8,
            3 => ElemType::U16,
            4 => ElemType::I16,
            5 => ElemType::U32,
            6 => ElemType::I32,
            7 => ElemType::F32,
            _ => return None,
        })
    }
}

/// Why a model file was rejected. Every variant names the offending part, so the message alone is actionable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum ModelFileError {
    /// The file is shorter than its header or than the length the header declares.
    Truncated {
        /// Bytes the header (or the minimum header) requires.
        expected: usize,
        /// Bytes present.
        actual: usize,
    },
    /// The file is longer than the length its header declares.
    TrailingBytes {
        /// Length declared in the header.
        declared: usize,
        /// Bytes present.
        actual: usize,
    },
    /// The first 8 bytes are not [`MAGIC`]: not a supine model file.
    BadMagic,
    /// The container layout version is not one this build reads.
    UnsupportedContainerVersion {
        /// Version in the file.
        found: u16,
    },
    /// The file holds another kind of model than the caller asked for.
    WrongKind {
        /// Kind the caller expected.
        expected: Tag,
        /// Kind in the file.
        found: Tag,
    },
    /// The kind's format version is not one this build reads.
    UnsupportedKindVersion {
        /// Kind of the file.
        kind: Tag,
        /// Version in the file.
        found: u16,
        /// Version this build reads.
        supported: u16,
    },
    /// The CRC-32C over the file does not match the stored one: the file is corrupt.
    ChecksumMismatch {
        /// CRC stored in the header.
        stored: u32,
        /// CRC computed over the bytes.
        computed: u32,
    },
    /// The section table is malformed (too many entries, or it runs past the data).
    BadSectionTable,
    /// A section has an unknown element type code.
    UnknownElementType {
        /// Section tag.
        tag: Tag,
        /// The code found.
        code: u8,
    },
    /// A section's data lies (partly) outside the file.
    SectionOutOfBounds {
        /// Section tag.
        tag: Tag,
    },
    /// A section's data does not start at a multiple of [`SECTION_ALIGN`].
    MisalignedSection {
        /// Section tag.
        tag: Tag,
    },
    /// Two sections share a tag.
    DuplicateSection {
        /// Section tag.
        tag: Tag,
    },
    /// A section the kind requires is absent.
    MissingSection {
        /// Section tag.
        tag: Tag,
    },
    /// A section has another element type than the kind requires.
    WrongElementType {
        /// Section tag.
        tag: Tag,
        /// Type the kind requires.
        expected: ElemType,
        /// Type in the file.
        found: ElemType,
    },
    /// A section has another element count than the kind's header implies.
    WrongSectionLength {
        /// Section tag.
        tag: Tag,
        /// Count required.
        expected: usize,
        /// Count in the file.
        found: usize,
    },
    /// The data of a section passed all structural checks but violates a rule of the file kind.
    InvalidData {
        /// Section tag.
        tag: Tag,
        /// What is wrong.
        what: &'static str,
    },
}

/// Formats a tag as text, with non-printable bytes escaped.
struct TagDisplay(Tag);

impl fmt::Display for TagDisplay {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for &b in &self.0 {
            if b.is_ascii_graphic() {
                write!(f, "{}", b as char)?;
            } else {
                write!(f, "\\x{b:02x}")?;
            }
        }
        Ok(())
    }
}

impl fmt::Display for ModelFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use ModelFileError::*;
        match *self {
            Truncated { expected, actual } => {
                write!(f, "model file truncated: {actual} bytes, expected {expected}")
            }
            TrailingBytes { declared, actual } => write!(
                f,
                "model file has trailing bytes: {actual} bytes, header declares {declared}"
            ),
            BadMagic => write!(f, "not a supine model file (bad magic)"),
            UnsupportedContainerVersion { found } => write!(
                f,
                "unsupported model container version {found} (this build reads {CONTAINER_VERSION})"
            ),
            WrongKind { expected, found } => write!(
                f,
                "wrong model kind: file holds '{}', expected '{}'",
                TagDisplay(found),
                TagDisplay(expected)
            ),
            UnsupportedKindVersion {
                kind,
                found,
                supported,
            } => write!(
                f,
                "unsupported '{}' model format version {found} (this build reads {supported})",
                TagDisplay(kind)
            ),
            ChecksumMismatch { stored, computed } => write!(
                f,
                "model file corrupt: CRC-32C {computed:#010x} does not match stored {stored:#010x}"
            ),
            BadSectionTable => write!(f, "model file section table is malformed"),
            UnknownElementType { tag, code } => {
                write!(f, "section '{}' has unknown element type {code}", TagDisplay(tag))
            }
            SectionOutOfBounds { tag } => {
                write!(f, "section '{}' lies outside the file", TagDisplay(tag))
            }
            MisalignedSection { tag } => write!(
                f,
                "section '{}' is not aligned to {SECTION_ALIGN} bytes",
                TagDisplay(tag)
            ),
            DuplicateSection { tag } => write!(f, "section '{}' appears twice", TagDisplay(tag)),
            MissingSection { tag } => write!(f, "required section '{}' is missing", TagDisplay(tag)),
            WrongElementType { tag, expected, found } => write!(
                f,
                "section '{}' has element type {found:?}, expected {expected:?}",
                TagDisplay(tag)
            ),
            WrongSectionLength { tag, expected, found } => write!(
                f,
                "section '{}' has {found} elements, expected {expected}",
                TagDisplay(tag)
            ),
            InvalidData { tag, what } => {
                write!(f, "section '{}' is invalid: {what}", TagDisplay(tag))
            }
        }
    }
}

impl core::error::Error for ModelFileError {}

/// An element type that a section can hold, decoded from little-endian bytes.
pub trait LeElement: Copy + 'static {
    /// The table code of this type.
    const TYPE: ElemType;
    /// Decode one element from exactly `TYPE.size()` bytes.
    fn from_le(bytes: &[u8]) -> Self;
}

macro_rules! le_element {
    ($t:ty, $e:expr, $n:expr) => {
        impl LeElement for $t {
            const TYPE: ElemType = $e;
            #[inline]
            fn from_le(bytes: &[u8]) -> Self {
                let mut a = [0u8; $n];
                a.copy_from_slice(&bytes[..$n]);
                <$t>::from_le_bytes(a)
            }
        }
    };
}
le_element!(u8, ElemType::U8, 1);
le_element!(i8, ElemType::I8, 1);
le_element!(u16, ElemType::U16, 2);
le_element!(i16, ElemType::I16, 2);
le_element!(u32, ElemType::U32, 4);
le_element!(i32, ElemType::I32, 4);
le_element!(f32, ElemType::F32, 4);

/// A borrowed, zero-copy view of `len()` little-endian elements of type `T`.
#[derive(Clone, Copy, Debug)]
pub struct LeSlice<'a, T: LeElement> {
    bytes: &'a [u8],
    _t: PhantomData<T>,
}

impl<'a, T: LeElement> LeSlice<'a, T> {
    /// An empty view.
    pub const fn empty() -> Self {
        Self {
            bytes: &[],
            _t: PhantomData,
        }
    }

    /// Number of elements.
    #[inline]
    pub fn len(&self) -> usize {
        self.bytes.len() / T::TYPE.size()
    }

    /// True when the view holds no element.
    #[inline]
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Element `i`, or `None` past the end.
    #[inline]
    pub fn get(&self, i: usize) -> Option<T> {
        let s = T::TYPE.size();
        self.bytes.get(i * s..i * s + s).map(T::from_le)
    }

    /// Element `i`. Panics when `i >= len()`: an indexing bug in the caller, never a consequence of bad file bytes
    /// (file kinds validate every stored index at load time).
    #[inline]
    pub fn at(&self, i: usize) -> T {
        let s = T::TYPE.size();
        T::from_le(&self.bytes[i * s..i * s + s])
    }

    /// Elements `[start, start + n)` as a view, or `None` when out of range.
    pub fn sub(&self, start: usize, n: usize) -> Option<Self> {
        let s = T::TYPE.size();
        let bytes = self
            .bytes
            .get(start.checked_mul(s)?..start.checked_add(n)?.checked_mul(s)?)?;
        Some(Self {
            bytes,
            _t: PhantomData,
        })
    }

    /// Iterate over the elements.
    pub fn iter(&self) -> impl ExactSizeIterator<Item = T> + 'a {
        self.bytes.chunks_exact(T::TYPE.size()).map(T::from_le)
    }

    /// The raw little-endian bytes.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }
}

/// One entry of the section table, validated.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Section<'a> {
    /// Section tag.
    pub tag: Tag,
    /// Element type.
    pub elem: ElemType,
    /// Element count.
    pub count: usize,
    /// The section's bytes (`count * elem.size()` of them).
    pub bytes: &'a [u8],
}

impl<'a> Section<'a> {
    /// View the section as elements of `T`; fails when the stored type differs.
    pub fn view<T: LeElement>(&self) -> Result<LeSlice<'a, T>, ModelFileError> {
        if self.elem != T::TYPE {
            return Err(ModelFileError::WrongElementType {
                tag: self.tag,
                expected: T::TYPE,
                found: self.elem,
            });
        }
        Ok(LeSlice {
            bytes: self.bytes,
            _t: PhantomData,
        })
    }
}

/// A validated model file: header fields plus its section table, borrowed from the bytes.
#[derive(Clone, Copy, Debug)]
pub struct ModelFile<'a> {
    bytes: &'a [u8],
    kind: Tag,
    kind_version: u16,
    sections: usize,
}

fn u16_at(b: &[u8], o: usize) -> u16 {
    u16::from_le_bytes([b[o], b[o + 1]])
}

fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]])
}

fn tag_at(b: &[u8], o: usize) -> Tag {
    [b[o], b[o + 1], b[o + 2], b[o + 3]]
}

impl<'a> ModelFile<'a> {
    /// Validate `bytes` as a model file of kind `kind` in format version `kind_version` (the only one the caller
    /// reads). Checks, in order: length, magic, container version, kind, kind version, declared length, CRC-32C,
    /// then every section entry (element type, bounds, alignment, unique tags).
    pub fn parse(bytes: &'a [u8], kind: Tag, kind_version: u16) -> Result<Self, ModelFileError> {
        if bytes.len() < HEADER_LEN {
            return Err(ModelFileError::Truncated {
                expected: HEADER_LEN,
                actual: bytes.len(),
            });
        }
        if bytes[0..8] != MAGIC {
            return Err(ModelFileError::BadMagic);
        }
        let container = u16_at(bytes, 8);
        if container != CONTAINER_VERSION {
            return Err(ModelFileError::UnsupportedContainerVersion { found: container });
        }
        let found_kind = tag_at(bytes, 12);
        if found_kind != kind {
            return Err(ModelFileError::WrongKind {
                expected: kind,
                found: found_kind,
            });
        }
        let found_version = u16_at(bytes, 16);
        if found_version != kind_version {
            return Err(ModelFileError::UnsupportedKindVersion {
                kind,
                found: found_version,
                supported: kind_version,
            });
        }
        let total = u32_at(bytes, 20) as usize;
        if bytes.len() < total || total < HEADER_LEN {
            return Err(ModelFileError::Truncated {
                expected: total.max(HEADER_LEN),
                actual: bytes.len(),
            });
        }
        if bytes.len() > total {
            return Err(ModelFileError::TrailingBytes {
                declared: total,
                actual: bytes.len(),
            });
        }
        let stored = u32_at(bytes, 24);
        let computed = file_crc(bytes);
        if stored != computed {
            return Err(ModelFileError::ChecksumMismatch { stored, computed });
        }
        let n = u16_at(bytes, 10) as usize;
        if n > MAX_SECTIONS || HEADER_LEN + n * SECTION_ENTRY_LEN > total {
            return Err(ModelFileError::BadSectionTable);
        }
        let file = ModelFile {
            bytes,
            kind,
            kind_version,
            sections: n,
        };
        for i in 0..n {
            let s = file.entry(i)?;
            for j in 0..i {
                if tag_at(bytes, HEADER_LEN + j * SECTION_ENTRY_LEN) == s.tag {
                    return Err(ModelFileError::DuplicateSection { tag: s.tag });
                }
            }
        }
        Ok(file)
    }

    /// Decode and check table entry `i` (`i < sections`).
    fn entry(&self, i: usize) -> Result<Section<'a>, ModelFileError> {
        let o = HEADER_LEN + i * SECTION_ENTRY_LEN;
        let b = self.bytes;
        let tag = tag_at(b, o);
        let code = b[o + 4];
        let elem = ElemType::from_code(code).ok_or(ModelFileError::UnknownElementType { tag, code })?;
        let offset = u32_at(b, o + 8) as usize;
        let count = u32_at(b, o + 12) as usize;
        if !offset.is_multiple_of(SECTION_ALIGN) {
            return Err(ModelFileError::MisalignedSection { tag });
        }
        let table_end = HEADER_LEN + self.sections * SECTION_ENTRY_LEN;
        let len = count
            .checked_mul(elem.size())
            .ok_or(ModelFileError::SectionOutOfBounds { tag })?;
        let end = offset
            .checked_add(len)
            .ok_or(ModelFileError::SectionOutOfBounds { tag })?;
        if offset < table_end || end > b.len() {
            return Err(ModelFileError::SectionOutOfBounds { tag });
        }
        Ok(Section {
            tag,
            elem,
            count,
            bytes: &b[offset..end],
        })
    }

    /// Kind tag of the file.
    pub fn kind(&self) -> Tag {
        self.kind
    }

    /// Format version of the kind.
    pub fn kind_version(&self) -> u16 {
        self.kind_version
    }

    /// Total size of the file in bytes.
    pub fn len(&self) -> usize {
        self.bytes.len()
    }

    /// Always false for a validated file (the header alone is 32 bytes); present for API symmetry with `len`.
    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The CRC-32C stored in (and verified against) the file.
    pub fn crc(&self) -> u32 {
        u32_at(self.bytes, 24)
    }

    /// Number of sections.
    pub fn section_count(&self) -> usize {
        self.sections
    }

    /// Section number `i` in table order, or `None` past the end.
    pub fn section_at(&self, i: usize) -> Option<Section<'a>> {
        if i < self.sections {
            self.entry(i).ok()
        } else {
            None
        }
    }

    /// The section tagged `tag`, or [`ModelFileError::MissingSection`].
    pub fn section(&self, tag: Tag) -> Result<Section<'a>, ModelFileError> {
        for i in 0..self.sections {
            if tag_at(self.bytes, HEADER_LEN + i * SECTION_ENTRY_LEN) == tag {
                return self.entry(i);
            }
        }
        Err(ModelFileError::MissingSection { tag })
    }

    /// The section tagged `tag` as `T` elements, requiring exactly `count` of them when `count` is `Some`.
    pub fn typed<T: LeElement>(
        &self,
        tag: Tag,
        count: Option<usize>,
    ) -> Result<LeSlice<'a, T>, ModelFileError> {
        let s = self.section(tag)?;
        let v = s.view::<T>()?;
        if let Some(expected) = count
            && expected != s.count
        {
            return Err(ModelFileError::WrongSectionLength {
                tag,
                expected,
                found: s.count,
            });
        }
        Ok(v)
    }
}

/// CRC-32C of a whole file image, skipping the CRC field itself (bytes 24..28).
fn file_crc(bytes: &[u8]) -> u32 {
    let s = crc32c_update(0xFFFF_FFFF, &bytes[..24]);
    crc32c_update(s, &bytes[28..]) ^ 0xFFFF_FFFF
}

/// One section to write: tag, element type and the already little-endian encoded bytes.
#[derive(Clone, Copy, Debug)]
pub struct SectionData<'a> {
    /// Section tag.
    pub tag: Tag,
    /// Element type.
    pub elem: ElemType,
    /// Little-endian element bytes; the length must be a multiple of `elem.size()`.
    pub bytes: &'a [u8],
}

/// Why [`fn@write`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum WriteError {
    /// More than [`MAX_SECTIONS`] sections.
    TooManySections,
    /// A section's byte length is not a multiple of its element size.
    RaggedSection {
        /// Section tag.
        tag: Tag,
    },
    /// The output buffer is smaller than [`encoded_len`].
    BufferTooSmall {
        /// Bytes needed.
        needed: usize,
    },
    /// The file would exceed 4 GiB.
    TooLarge,
}

impl fmt::Display for WriteError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            WriteError::TooManySections => write!(f, "more than {MAX_SECTIONS} sections"),
            WriteError::RaggedSection { tag } => {
                write!(
                    f,
                    "section '{}' length is not a multiple of its element size",
                    TagDisplay(tag)
                )
            }
            WriteError::BufferTooSmall { needed } => {
                write!(f, "output buffer too small: {needed} bytes needed")
            }
            WriteError::TooLarge => write!(f, "model file would exceed 4 GiB"),
        }
    }
}

impl core::error::Error for WriteError {}

const fn align_up(x: usize) -> usize {
    x.div_ceil(SECTION_ALIGN) * SECTION_ALIGN
}

/// Bytes a file with these sections occupies.
pub fn encoded_len(sections: &[SectionData<'_>]) -> usize {
    let mut at = align_up(HEADER_LEN + sections.len() * SECTION_ENTRY_LEN);
    for s in sections {
        at = align_up(at + s.bytes.len());
    }
    at
}

/// Write a model file of `kind` / `kind_version` with `sections` (in this order) into `out`; returns the length.
/// Padding bytes are zero, so equal inputs give byte-identical files.
pub fn write(
    kind: Tag,
    kind_version: u16,
    sections: &[SectionData<'_>],
    out: &mut [u8],
) -> Result<usize, WriteError> {
    if sections.len() > MAX_SECTIONS {
        return Err(WriteError::TooManySections);
    }
    for s in sections {
        if !s.bytes.len().is_multiple_of(s.elem.size()) {
            return Err(WriteError::RaggedSection { tag: s.tag });
        }
    }
    let total = encoded_len(sections);
    if total > u32::MAX as usize {
        return Err(WriteError::TooLarge);
    }
    if out.len() < total {
        return Err(WriteError::BufferTooSmall { needed: total });
    }
    let out = &mut out[..total];
    out.fill(0);
    out[0..8].copy_from_slice(&MAGIC);
    out[8..10].copy_from_slice(&CONTAINER_VERSION.to_le_bytes());
    out[10..12].copy_from_slice(&(sections.len() as u16).to_le_bytes());
    out[12..16].copy_from_slice(&kind);
    out[16..18].copy_from_slice(&kind_version.to_le_bytes());
    out[20..24].copy_from_slice(&(total as u32).to_le_bytes());
    let mut at = align_up(HEADER_LEN + sections.len() * SECTION_ENTRY_LEN);
    for (i, s) in sections.iter().enumerate() {
        let e = HEADER_LEN + i * SECTION_ENTRY_LEN;
        out[e..e + 4].copy_from_slice(&s.tag);
        out[e + 4] = s.elem as u8;
        out[e + 8..e + 12].copy_from_slice(&(at as u32).to_le_bytes());
        out[e + 12..e + 16].copy_from_slice(&((s.bytes.len() / s.elem.size()) as u32).to_le_bytes());
        out[at..at + s.bytes.len()].copy_from_slice(s.bytes);
        at = align_up(at + s.bytes.len());
    }
    let crc = file_crc(out);
    out[24..28].copy_from_slice(&crc.to_le_bytes());
    Ok(total)
}

#[cfg(test)]
mod tests {
    use super::*;

    const KIND: Tag = *b"TEST";

    fn sample(buf: &mut [u8]) -> usize {
        let a: [u8; 12] = [1, 0, 0, 0, 2, 0, 0, 0, 3, 0, 0, 0];
        let b: [u8; 5] = *b"hello";
        let secs = [
            SectionData {
                tag: *b"NUMS",
                elem: ElemType::U32,
                bytes: &a,
            },
            SectionData {
                tag: *b"TEXT",
                elem: ElemType::U8,
                bytes: &b,
            },
        ];
        write(KIND, 3, &secs, buf).unwrap()
    }

    #[test]
    fn round_trip_and_alignment() {
        let mut buf = [0u8; 256];
        let n = sample(&mut buf);
        assert_eq!(n % SECTION_ALIGN, 0);
        let f = ModelFile::parse(&buf[..n], KIND, 3).unwrap();
        assert_eq!(f.section_count(), 2);
        let nums = f.typed::<u32>(*b"NUMS", Some(3)).unwrap();
        assert_eq!(
            nums.iter().collect::<heapless::Vec<u32, 4>>().as_slice(),
            &[1, 2, 3]
        );
        assert_eq!(f.section(*b"TEXT").unwrap().bytes, b"hello");
        assert_eq!(
            f.section(*b"NUMS").unwrap().bytes.as_ptr() as usize % 4,
            buf.as_ptr() as usize % 4
        );
        assert_eq!(
            f.typed::<u32>(*b"NOPE", None).unwrap_err(),
            ModelFileError::MissingSection { tag: *b"NOPE" }
        );
        assert!(matches!(
            f.typed::<f32>(*b"NUMS", None),
            Err(ModelFileError::WrongElementType { .. })
        ));
        assert!(matches!(
            f.typed::<u32>(*b"NUMS", Some(4)),
            Err(ModelFileError::WrongSectionLength { .. })
        ));
    }

    #[test]
    fn every_corruption_is_a_distinct_error() {
        let mut buf = [0u8; 256];
        let n = sample(&mut buf);
        let good = &buf[..n];
        let mut bad = [0u8; 256];

        bad[..n].copy_from_slice(good);
        bad[0] ^= 1;
        assert_eq!(
            ModelFile::parse(&bad[..n], KIND, 3).unwrap_err(),
            ModelFileError::BadMagic
        );

        assert!(matches!(
            ModelFile::parse(good, KIND, 4),
            Err(ModelFileError::UnsupportedKindVersion { found: 3, .. })
        ));
        assert!(matches!(
            ModelFile::parse(good, *b"BODY", 3),
            Err(ModelFileError::WrongKind { .. })
        ));

        bad[..n].copy_from_slice(good);
        bad[8] = 9;
        assert_eq!(
            ModelFile::parse(&bad[..n], KIND, 3).unwrap_err(),
            ModelFileError::UnsupportedContainerVersion { found: 9 }
        );

        for cut in [0, 10, 31, 32, n - 1] {
            assert!(matches!(
                ModelFile::parse(&good[..cut], KIND, 3),
                Err(ModelFileError::Truncated { .. })
            ));
        }
        assert!(matches!(
            ModelFile::parse(&buf[..n + 1], KIND, 3),
            Err(ModelFileError::TrailingBytes { .. })
        ));

        // A flip anywhere past the identifying fields is caught by the CRC (or by the length check for the length).
        for i in 18..n {
            bad[..n].copy_from_slice(good);
            bad[i] ^= 0x10;
            let e = ModelFile::parse(&bad[..n], KIND, 3).unwrap_err();
            match i {
                20..24 => assert!(matches!(
                    e,
                    ModelFileError::Truncated { .. } | ModelFileError::TrailingBytes { .. }
                )),
                _ => assert!(
                    matches!(e, ModelFileError::ChecksumMismatch { .. }),
                    "byte {i}: {e:?}"
                ),
            }
        }
    }

    #[test]
    fn arbitrary_bytes_never_panic() {
        // A cheap deterministic fuzz: xorshift bytes, with a valid prefix half the time.
        let mut good = [0u8; 256];
        let n = sample(&mut good);
        let mut x: u32 = 0x1234_5678;
        let mut buf = [0u8; 128];
        for round in 0..2000 {
            for b in buf.iter_mut() {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                *b = x as u8;
            }
            if round % 2 == 0 {
                buf[..32].copy_from_slice(&good[..32]);
            }
            let len = (x as usize) % buf.len();
            let _ = ModelFile::parse(&buf[..len], KIND, 3);
        }
        assert!(ModelFile::parse(&good[..n], KIND, 3).is_ok());
    }

    #[test]
    fn writer_rejects_bad_input() {
        let mut buf = [0u8; 64];
        let odd = [0u8; 3];
        let secs = [SectionData {
            tag: *b"ODD_",
            elem: ElemType::U16,
            bytes: &odd,
        }];
        assert_eq!(
            write(KIND, 1, &secs, &mut buf),
            Err(WriteError::RaggedSection { tag: *b"ODD_" })
        );
        let big = [0u8; 64];
        let secs = [SectionData {
            tag: *b"BIG_",
            elem: ElemType::U8,
            bytes: &big,
        }];
        assert!(matches!(
            write(KIND, 1, &secs, &mut buf),
            Err(WriteError::BufferTooSmall { .. })
        ));
    }
}
