//! The model maps section (kind [`crate::layout::SectionKind::ModelMaps`], tag 10): the two programs a
//! feedback-linearizable or differentially flat plant's controller evaluates around the image's linear
//! law (§3.1.2, law (3.17)), the initial values of the controller's own states, their byte layout,
//! validation ([`ModelMaps::decode`]) and writing ([`write_body`]).
//!
//! With this section the image's linear machinery (balls, step table, `K`, `P`; header dims `n`, `m`)
//! works on the linear coordinates ξ (n values) and produces `w` (m values), while the plant has its own
//! state `x` (`n_plant` values) and input `u` (`m_plant` values). The controller may keep `n_ext` states
//! ζ of its own between periods (a dynamic extension, as a differentially flat plant needs: its thrust and
//! the thrust's rate); `n_ext = 0` for a feedback-linearizable plant:
//! * `coords`: `(x, ζ) ↦ ξ` (inputs: the `n_plant` slots of `x`, then the `n_ext` of ζ; outputs: `n`);
//! * `input_map`: `(x, ζ, w) ↦ (u, ζ⁺)` (inputs: `n_plant + n_ext + m` slots, `x` first, then ζ, then
//!   `w`; outputs: `m_plant + n_ext`, the plant's input `u` first, then ζ⁺, the controller's states at the
//!   next period).
//!
//! # Body layout (little endian)
//!
//! | offset | size | field |
//! |---|---|---|
//! | 0 | 1 | `n_plant`, `1..=MAX_N` |
//! | 1 | 1 | `m_plant`, `1..=MAX_M` |
//! | 2 | 1 | `n_ext`, the number of controller states, `0..=MAX_EXT` |
//! | 3 | 1 | reserved, 0 |
//! | 4 | 4 | `coords_len`: bytes of the `coords` program |
//! | 8 | 4 | `input_map_len`: bytes of the `input_map` program |
//! | 12 | `4·n_ext` | ζ0: the controller states' initial values, `n_ext` f32, each finite |
//! | 12 + 4·n_ext | `coords_len` | the `coords` program ([`crate::program`]'s layout), then zeros to a multiple of 4 |
//! | … | `input_map_len` | the `input_map` program, then zeros to a multiple of 4 |
//!
//! With `n_ext = 0` there are no ζ0 words and byte 2 is 0: the layout (and every such body's bytes) is
//! the one of the feedback-linearizable section before the extension. The body is exactly that long; each
//! program is validated by [`Program::decode`] and its input and output counts are checked against the
//! dimensions above. Padding keeps each program's constant pool 4-byte aligned relative to the section,
//! and zero padding gives one content one encoding.
//!
//! An image with this section is feedforward (the directory refuses it in a PWA image). Its fallback acts
//! on the plant: `Zero`, `Constant` (`m_plant` values) and `Hold` apply a plant input without running
//! `input_map` (ζ is then left as it is), the input box has `m_plant` bounds, and a `Linear` fallback is
//! refused (its gain would act on ξ). The evaluator's [`crate::eval::Controller::step_plant`] runs the
//! maps and keeps ζ (ζ0 at every reset).

use crate::capacity::{MAX_EXT, MAX_M, MAX_N};
use crate::error::{Dim, Field, ImageError, ModelMap, Pos};
use crate::program::Program;
use crate::raw::{check_dim, check_finite, f32_at, floats, sat16, sat32, u32_at_byte};

/// Bytes of the section's fixed header.
pub const MAPS_HEADER_LEN: usize = 12;

/// `len` rounded up to a multiple of 4 (saturating).
const fn padded(len: usize) -> usize {
    len.saturating_add(3) & !3
}

/// Bytes of a model maps body with `n_ext` controller states whose programs have these lengths.
pub const fn body_len(n_ext: usize, coords_len: usize, input_map_len: usize) -> usize {
    MAPS_HEADER_LEN
        .saturating_add(n_ext.saturating_mul(4))
        .saturating_add(padded(coords_len))
        .saturating_add(padded(input_map_len))
}

/// The validated model maps of an image: the plant's dimensions, the controller states' initial values
/// and the two programs, borrowed from the section body.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelMaps<'a> {
    body: &'a [u8],
    n_plant: u8,
    m_plant: u8,
    n_ext: u8,
    /// ζ0: `4·n_ext` bytes.
    ext_init: &'a [u8],
    coords: Program<'a>,
    input_map: Program<'a>,
    coords_bytes: &'a [u8],
    input_map_bytes: &'a [u8],
}

impl<'a> ModelMaps<'a> {
    /// Validates a section body for an image of linear dimensions `n` (ξ) and `m` (w); see the module
    /// docs for every check.
    pub fn decode(body: &'a [u8], n: usize, m: usize) -> Result<Self, ImageError> {
        let byte = |i: usize| body.get(i).copied().unwrap_or(0);
        if body.len() < MAPS_HEADER_LEN {
            return Err(ImageError::FieldLength {
                field: Field::ModelMaps,
                expected: sat32(MAPS_HEADER_LEN),
                found: sat32(body.len()),
            });
        }
        let (n_plant, m_plant) = (byte(0), byte(1));
        check_dim(Dim::PlantN, n_plant.into(), 1, MAX_N)?;
        check_dim(Dim::PlantM, m_plant.into(), 1, MAX_M)?;
        let n_ext = byte(2);
        check_dim(Dim::ExtStates, n_ext.into(), 0, MAX_EXT)?;
        if byte(3) != 0 {
            return Err(ImageError::MapsPadding { offset: 3 });
        }
        let ne = usize::from(n_ext);
        let coords_len = u32_at_byte(body, 4) as usize;
        let input_map_len = u32_at_byte(body, 8) as usize;
        let expected = body_len(ne, coords_len, input_map_len);
        if body.len() != expected {
            return Err(ImageError::FieldLength {
                field: Field::ModelMaps,
                expected: sat32(expected),
                found: sat32(body.len()),
            });
        }
        // From here on both lengths are bounded by the body's length, so nothing below overflows.
        let c0 = MAPS_HEADER_LEN + 4 * ne;
        let i0 = c0 + padded(coords_len);
        for (start, len) in [(c0, coords_len), (i0, input_map_len)] {
            for i in start + len..start + padded(len) {
                if byte(i) != 0 {
                    return Err(ImageError::MapsPadding { offset: sat32(i) });
                }
            }
        }
        let ext_init = body.get(MAPS_HEADER_LEN..c0).unwrap_or(&[]);
        check_finite(Field::ExtInit, ext_init, |i| Pos(sat16(i), 0, 0))?;
        let coords_bytes = body.get(c0..c0 + coords_len).unwrap_or(&[]);
        let input_map_bytes = body.get(i0..i0 + input_map_len).unwrap_or(&[]);
        let coords = Program::decode(coords_bytes)?;
        let input_map = Program::decode(input_map_bytes)?;
        let (np, mp) = (usize::from(n_plant), usize::from(m_plant));
        for (map, p, inputs, outputs) in [
            (ModelMap::Coords, &coords, np + ne, n),
            (ModelMap::InputMap, &input_map, np + ne + m, mp + ne),
        ] {
            if p.n_inputs() != inputs {
                return Err(ImageError::MapInputs {
                    map,
                    expected: sat16(inputs),
                    found: sat16(p.n_inputs()),
                });
            }
            if p.n_outputs() != outputs {
                return Err(ImageError::MapOutputs {
                    map,
                    expected: sat16(outputs),
                    found: sat16(p.n_outputs()),
                });
            }
        }
        Ok(ModelMaps {
            body,
            n_plant,
            m_plant,
            n_ext,
            ext_init,
            coords,
            input_map,
            coords_bytes,
            input_map_bytes,
        })
    }

    /// The plant's state dimension.
    pub fn n_plant(&self) -> usize {
        self.n_plant.into()
    }

    /// The plant's input dimension.
    pub fn m_plant(&self) -> usize {
        self.m_plant.into()
    }

    /// The number of controller states `n_ext` (0 without a dynamic extension).
    pub fn n_ext(&self) -> usize {
        self.n_ext.into()
    }

    /// ζ0_i, the initial value of controller state `i` (`i < n_ext`); 0.0 out of range.
    pub fn ext_init(&self, i: usize) -> f32 {
        if i < self.n_ext() {
            f32_at(self.ext_init, i)
        } else {
            0.0
        }
    }

    /// ζ0: the `n_ext` initial values of the controller states, in order.
    pub fn ext_inits(&self) -> impl Iterator<Item = f32> + 'a {
        floats(self.ext_init)
    }

    /// `coords: (x, ζ) ↦ ξ`.
    pub fn coords(&self) -> Program<'a> {
        self.coords
    }

    /// `input_map: (x, ζ, w) ↦ (u, ζ⁺)`.
    pub fn input_map(&self) -> Program<'a> {
        self.input_map
    }

    /// The bytes of the `coords` program (without padding).
    pub fn coords_bytes(&self) -> &'a [u8] {
        self.coords_bytes
    }

    /// The bytes of the `input_map` program (without padding).
    pub fn input_map_bytes(&self) -> &'a [u8] {
        self.input_map_bytes
    }

    /// The section body as stored.
    pub fn body(&self) -> &'a [u8] {
        self.body
    }
}

/// Writes a model maps body (module docs) from the controller states' initial values ζ0 (`ext_init`,
/// empty without a dynamic extension) and two program bodies into `out`; returns the bytes written
/// ([`body_len`]). Checks only that the values fit their fields and `out` is long enough; the decoder is
/// the judge of the content.
pub fn write_body(
    out: &mut [u8],
    n_plant: usize,
    m_plant: usize,
    ext_init: &[f32],
    coords: &[u8],
    input_map: &[u8],
) -> Result<usize, ImageError> {
    let total = body_len(ext_init.len(), coords.len(), input_map.len());
    let (Ok(np), Ok(mp), Ok(ne), Ok(cl), Ok(il)) = (
        u8::try_from(n_plant),
        u8::try_from(m_plant),
        u8::try_from(ext_init.len()),
        u32::try_from(coords.len()),
        u32::try_from(input_map.len()),
    ) else {
        return Err(ImageError::Encode);
    };
    let Some(buf) = out.get_mut(..total) else {
        return Err(ImageError::BufferTooSmall {
            needed: sat32(total),
        });
    };
    buf.fill(0);
    let mut header = [0u8; MAPS_HEADER_LEN];
    header[0] = np;
    header[1] = mp;
    header[2] = ne;
    header[4..8].copy_from_slice(&cl.to_le_bytes());
    header[8..12].copy_from_slice(&il.to_le_bytes());
    for (i, v) in ext_init.iter().enumerate() {
        let at = MAPS_HEADER_LEN + 4 * i;
        buf.get_mut(at..at + 4)
            .ok_or(ImageError::Encode)?
            .copy_from_slice(&v.to_le_bytes());
    }
    let c0 = MAPS_HEADER_LEN + 4 * ext_init.len();
    let i0 = c0 + padded(coords.len());
    for (start, bytes) in [(0, &header[..]), (c0, coords), (i0, input_map)] {
        buf.get_mut(start..start + bytes.len())
            .ok_or(ImageError::Encode)?
            .copy_from_slice(bytes);
    }
    Ok(total)
}
