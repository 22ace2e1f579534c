//! The fixed header and the section directory: parsing them from bytes ([`Header::parse`],
//! [`Directory::parse`]), the CRC, and writing both ([`write_image`]). This module knows where sections
//! are and what kind each is, not what they contain; the contents are parsed and validated by
//! [`crate::image`] (and [`crate::pwa`] for the PWA tables). Layout table in [`crate::image`].

use crate::capacity::{HEADER_LEN, MAX_SECTIONS};
use crate::error::{Dim, ImageError};
use crate::layout::{
    Dims, Mode, SectionKind, CRC_OFFSET, DIR_ENTRY_LEN, FORMAT_VERSION, MAGIC, SECTION_COUNT_OFFSET,
};
use crate::raw::{check_dim, sat16, sat32, u16_at, u32_at, u32_at_byte};

const CRC32: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// The fixed header as read from the bytes, after checking only length, magic, version and reserved
/// byte (see [`Header::parse`]); the rest is checked by [`crate::image::decode`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Header {
    /// Format version (equal to [`FORMAT_VERSION`] once parsed).
    pub version: u16,
    /// Raw mode byte (see [`Mode::from_u8`]).
    pub mode: u8,
    /// Dimensions as declared.
    pub dims: Dims,
    /// Number of entries of the section directory, as declared.
    pub n_sections: u16,
    /// Sample period, seconds, as stored (not yet checked).
    pub period: f32,
    /// Length of everything after the header (directory and sections), as declared.
    pub payload_len: u32,
    /// CRC stored in the header.
    pub crc: u32,
}

impl Header {
    /// Reads the fixed header. Checks only what is needed to trust the layout: length, magic, version and
    /// the reserved byte.
    pub fn parse(bytes: &[u8]) -> Result<Header, ImageError> {
        let Some(h) = bytes.get(..HEADER_LEN) else {
            return Err(ImageError::Truncated {
                len: sat32(bytes.len()),
            });
        };
        let magic = [h[0], h[1], h[2], h[3]];
        if magic != MAGIC {
            return Err(ImageError::BadMagic { found: magic });
        }
        let version = u16_at(h, 4);
        if version != FORMAT_VERSION {
            return Err(ImageError::UnsupportedVersion { found: version });
        }
        if h[7] != 0 {
            return Err(ImageError::ReservedNotZero);
        }
        Ok(Header {
            version,
            mode: h[6],
            dims: Dims {
                n: u16_at(h, 8) as usize,
                m: u16_at(h, 10) as usize,
                n_locations: u16_at(h, 12) as usize,
                n_trajectories: u16_at(h, 14) as usize,
                n_partitions: u16_at(h, 16) as usize,
            },
            n_sections: u16_at(h, SECTION_COUNT_OFFSET),
            // u32_at indexes 4-byte words: word 5 is bytes 20..24, 6 is 24..28, 7 is 28..32.
            period: f32::from_bits(u32_at(h, 5)),
            payload_len: u32_at(h, 6),
            crc: u32_at(h, 7),
        })
    }
}

/// One entry of the section directory as stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DirEntry {
    /// Kind tag (a [`SectionKind`] if this build knows it).
    pub kind: u16,
    /// Reserved flags (0).
    pub flags: u16,
    /// Offset of the section's first byte from the start of the image.
    pub offset: u32,
    /// Length of the section in bytes.
    pub len: u32,
}

/// The validated section directory of an image: where each known section lies. Obtained from
/// [`Directory::parse`], which guarantees: between 1 and [`MAX_SECTIONS`] entries; flags zero; sections
/// stored back to back in directory order from the end of the directory to the end of the image (no gap,
/// overlap or unclaimed byte); kinds strictly increasing (so none twice); every kind known and admitted by
/// the mode; every kind the mode requires present.
#[derive(Clone, Copy, Debug)]
pub struct Directory<'a> {
    bytes: &'a [u8],
    count: usize,
    body: [Option<&'a [u8]>; SectionKind::ALL.len()],
}

impl<'a> Directory<'a> {
    /// Parses and checks the directory of `bytes` (a whole image whose header parsed and whose payload
    /// length matched) for an image of `mode`. Check order per entry: flags, placement, range, order,
    /// known kind, admitted by the mode; then unclaimed bytes, then required sections in kind order.
    pub fn parse(
        bytes: &'a [u8],
        n_sections: u16,
        mode: Mode,
    ) -> Result<Directory<'a>, ImageError> {
        let count = n_sections as usize;
        check_dim(Dim::Sections, count, 1, MAX_SECTIONS)?;
        let dir_end = HEADER_LEN + count * DIR_ENTRY_LEN;
        if dir_end > bytes.len() {
            return Err(ImageError::DirectoryTruncated {
                sections: n_sections,
            });
        }
        let mut body = [None; SectionKind::ALL.len()];
        let mut next = dir_end;
        let mut prev_kind = 0u16;
        for i in 0..count {
            let e = entry_at(bytes, i);
            let index = sat16(i);
            if e.flags != 0 {
                return Err(ImageError::SectionFlags { index });
            }
            if e.offset as usize != next {
                return Err(ImageError::SectionPlacement {
                    index,
                    expected: sat32(next),
                    found: e.offset,
                });
            }
            let end = next.saturating_add(e.len as usize);
            let Some(b) = bytes.get(next..end) else {
                return Err(ImageError::SectionOutOfRange { index });
            };
            if i > 0 && e.kind <= prev_kind {
                return Err(match SectionKind::from_u16(e.kind) {
                    Some(kind) if e.kind == prev_kind => ImageError::DuplicateSection { kind },
                    _ => ImageError::SectionOrder {
                        index,
                        kind: e.kind,
                    },
                });
            }
            let Some(kind) = SectionKind::from_u16(e.kind) else {
                return Err(ImageError::UnknownSection { kind: e.kind });
            };
            if !mode.admits(kind) {
                return Err(ImageError::UnexpectedSection { kind, mode });
            }
            if let Some(slot) = body.get_mut(kind.index()) {
                *slot = Some(b);
            }
            prev_kind = e.kind;
            next = end;
        }
        if next != bytes.len() {
            return Err(ImageError::UnclaimedBytes {
                offset: sat32(next),
            });
        }
        for &kind in mode.required_sections() {
            if body.get(kind.index()).copied().flatten().is_none() {
                return Err(ImageError::MissingSection { kind });
            }
        }
        Ok(Directory { bytes, count, body })
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.count
    }

    /// Whether the directory has no entries (never, once parsed).
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Entry `i` as stored; `None` out of range.
    pub fn entry(&self, i: usize) -> Option<DirEntry> {
        (i < self.count).then(|| entry_at(self.bytes, i))
    }

    /// The body of the section of `kind`, if present.
    pub fn section(&self, kind: SectionKind) -> Option<&'a [u8]> {
        self.body.get(kind.index()).copied().flatten()
    }
}

/// Directory entry `i` of `bytes` (total: missing bytes read as 0).
fn entry_at(bytes: &[u8], i: usize) -> DirEntry {
    let o = HEADER_LEN.saturating_add(i.saturating_mul(DIR_ENTRY_LEN));
    DirEntry {
        kind: u16_at(bytes, o),
        flags: u16_at(bytes, o.saturating_add(2)),
        offset: u32_at_byte(bytes, o.saturating_add(4)),
        len: u32_at_byte(bytes, o.saturating_add(8)),
    }
}

/// CRC over the header bytes before the CRC field and everything after the header.
fn crc_of(header_prefix: &[u8], payload: &[u8]) -> u32 {
    let mut d = CRC32.digest();
    d.update(header_prefix);
    d.update(payload);
    d.finalize()
}

/// The CRC that the header of `bytes` should carry for its current content (header bytes 0..28 and all
/// bytes after the header). Used by tools that patch images; errors if shorter than the header.
pub fn compute_crc(bytes: &[u8]) -> Result<u32, ImageError> {
    match (bytes.get(..CRC_OFFSET), bytes.get(HEADER_LEN..)) {
        (Some(prefix), Some(payload)) => Ok(crc_of(prefix, payload)),
        _ => Err(ImageError::Truncated {
            len: sat32(bytes.len()),
        }),
    }
}

/// A section's content for [`write_image`]: its kind tag, its encoded length and how to write it.
pub trait SectionWrite {
    /// Kind tag stored in the directory.
    fn kind(&self) -> u16;
    /// Exact number of bytes [`SectionWrite::write`] writes.
    fn encoded_len(&self) -> Result<usize, ImageError>;
    /// Writes the body into `out` (exactly `encoded_len()` bytes long); returns the bytes written.
    fn write(&self, out: &mut [u8]) -> Result<usize, ImageError>;
}

/// A section given as raw bytes (for tools and tests that write images the encoder would refuse).
#[derive(Clone, Copy, Debug)]
pub struct RawSection<'a> {
    /// Kind tag.
    pub kind: u16,
    /// Body.
    pub body: &'a [u8],
}

impl SectionWrite for RawSection<'_> {
    fn kind(&self) -> u16 {
        self.kind
    }
    fn encoded_len(&self) -> Result<usize, ImageError> {
        Ok(self.body.len())
    }
    fn write(&self, out: &mut [u8]) -> Result<usize, ImageError> {
        let dst = out.get_mut(..self.body.len()).ok_or(ImageError::Encode)?;
        dst.copy_from_slice(self.body);
        Ok(self.body.len())
    }
}

/// Total length of an image with these sections: header, directory and bodies.
pub fn image_len(sections: &[&dyn SectionWrite]) -> Result<usize, ImageError> {
    let mut total = HEADER_LEN + sections.len() * DIR_ENTRY_LEN;
    for s in sections {
        total = total
            .checked_add(s.encoded_len()?)
            .ok_or(ImageError::Encode)?;
    }
    Ok(total)
}

/// Writes header, directory and sections (in the order given) into `out`, with the payload length and
/// CRC filled in, and returns the bytes written. Checks nothing about the content: [`crate::image::encode`]
/// calls it only for validated images; tools and tests call it to write anything else. Fails with
/// [`ImageError::BufferTooSmall`] if `out` is too short, and with [`ImageError::Encode`] if a section
/// writes other than its `encoded_len` or the counts do not fit their fields.
pub fn write_image(
    out: &mut [u8],
    mode: u8,
    dims: Dims,
    period: f32,
    sections: &[&dyn SectionWrite],
) -> Result<usize, ImageError> {
    let total = image_len(sections)?;
    let n_sections = u16::try_from(sections.len()).map_err(|_| ImageError::Encode)?;
    let payload_len = u32::try_from(total - HEADER_LEN).map_err(|_| ImageError::Encode)?;
    let Some(buf) = out.get_mut(..total) else {
        return Err(ImageError::BufferTooSmall {
            needed: sat32(total),
        });
    };
    let mut offset = HEADER_LEN + sections.len() * DIR_ENTRY_LEN;
    for (i, s) in sections.iter().enumerate() {
        let len = s.encoded_len()?;
        let e = HEADER_LEN + i * DIR_ENTRY_LEN;
        let entry = buf
            .get_mut(e..e + DIR_ENTRY_LEN)
            .ok_or(ImageError::Encode)?;
        entry[0..2].copy_from_slice(&s.kind().to_le_bytes());
        entry[2..4].copy_from_slice(&0u16.to_le_bytes());
        entry[4..8].copy_from_slice(&sat32(offset).to_le_bytes());
        entry[8..12].copy_from_slice(&sat32(len).to_le_bytes());
        let body = buf
            .get_mut(offset..offset + len)
            .ok_or(ImageError::Encode)?;
        if s.write(body)? != len {
            return Err(ImageError::Encode);
        }
        offset += len;
    }
    let header = buf.get_mut(..HEADER_LEN).ok_or(ImageError::Encode)?;
    header[0..4].copy_from_slice(&MAGIC);
    header[4..6].copy_from_slice(&FORMAT_VERSION.to_le_bytes());
    header[6] = mode;
    header[7] = 0;
    header[8..10].copy_from_slice(&sat16(dims.n).to_le_bytes());
    header[10..12].copy_from_slice(&sat16(dims.m).to_le_bytes());
    header[12..14].copy_from_slice(&sat16(dims.n_locations).to_le_bytes());
    header[14..16].copy_from_slice(&sat16(dims.n_trajectories).to_le_bytes());
    header[16..18].copy_from_slice(&sat16(dims.n_partitions).to_le_bytes());
    header[18..20].copy_from_slice(&n_sections.to_le_bytes());
    header[20..24].copy_from_slice(&period.to_le_bytes());
    header[24..28].copy_from_slice(&payload_len.to_le_bytes());
    let crc = compute_crc(buf)?;
    buf[28..32].copy_from_slice(&crc.to_le_bytes());
    Ok(total)
}
