//! Structured mutation of reader inputs for the bounded fuzz test (`tests/tests/readers_fuzz.rs`).
//!
//! Each input format is mutated where its readers make decisions, not only byte by byte: text
//! formats get numbers swapped for extreme values (NaN, infinities, huge and negative counts,
//! grid limits), lines dropped, repeated and swapped; PNG files are edited chunk by chunk with
//! their CRCs recomputed (so the decoder's checks, not the CRC, meet the damage), header fields
//! first; PM files get their checksum recomputed after the damage for the same reason; other
//! binary files get bit flips, boundary integers and floats written over fields, truncation,
//! deletion and duplication of ranges. Deterministic for a given seed.

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// How an input is mutated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// UTF-8 text: TOML, CSV, camera paths, OBJ.
    Text,
    /// PNG: chunks edited, CRCs recomputed.
    Png,
    /// Progressive mesh (`.pm`): bytes damaged, trailing FNV-1a checksum recomputed.
    Pm,
    /// Any other binary file (EXR, TIFF).
    Binary,
}

/// Numbers that sit on the edges readers must handle.
const EXTREME_NUMBERS: [&str; 24] = [
    "NaN",
    "nan",
    "inf",
    "-inf",
    "-1",
    "0",
    "-0",
    "1e308",
    "-1e308",
    "1e-320",
    "4294967296",
    "18446744073709551616",
    "2147483648",
    "99999999999",
    "16385",
    "16386",
    "65536",
    "0.5",
    "-0.5",
    "",
    "x",
    "1e9",
    "255",
    "256",
];

/// Integers written over binary fields (little- and big-endian).
const EXTREME_U32: [u32; 11] = [
    0,
    1,
    2,
    0xFF,
    0xFFFF,
    16_385,
    16_386,
    1 << 24,
    0x7FFF_FFFF,
    0x8000_0000,
    0xFFFF_FFFF,
];

/// A seeded mutator.
pub struct Mutator {
    rng: SmallRng,
}

impl Mutator {
    pub fn new(seed: u64) -> Self {
        Self {
            rng: SmallRng::seed_from_u64(seed),
        }
    }

    /// One mutated copy of `input`: one to three mutations of the format's kind.
    pub fn mutate(&mut self, input: &[u8], format: Format) -> Vec<u8> {
        let mut b = input.to_vec();
        let rounds = self.rng.random_range(1..=3);
        for _ in 0..rounds {
            match format {
                Format::Text => self.text(&mut b),
                Format::Png => self.png(&mut b),
                Format::Pm => {
                    self.binary(&mut b);
                    // Most of the time keep the checksum right, so the parser meets the damage.
                    if b.len() > 8 && self.rng.random_bool(0.9) {
                        let body = b.len() - 8;
                        let sum = worldgen::pm::file::fnv1a(&b[..body]);
                        b[body..].copy_from_slice(&sum.to_le_bytes());
                    }
                }
                Format::Binary => self.binary(&mut b),
            }
        }
        b
    }

    fn pick(&mut self, n: usize) -> usize {
        if n == 0 {
            0
        } else {
            self.rng.random_range(0..n)
        }
    }

    fn text(&mut self, b: &mut Vec<u8>) {
        let text = String::from_utf8_lossy(b).into_owned();
        let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
        let n = lines.len();
        match self.rng.random_range(0..10) {
            // A number replaced by an extreme value (three times as likely as the others).
            0..=2 => {
                let spans = number_spans(&text);
                if spans.is_empty() {
                    return self.binary(b);
                }
                let (s, e) = spans[self.pick(spans.len())];
                let v = EXTREME_NUMBERS[self.pick(EXTREME_NUMBERS.len())];
                let mut out = text[..s].to_string();
                out.push_str(v);
                out.push_str(&text[e..]);
                *b = out.into_bytes();
                return;
            }
            3 if n > 0 => {
                lines.remove(self.pick(n));
            }
            4 if n > 0 => {
                let i = self.pick(n);
                let times = [1, 2, 10, 1000][self.pick(4)];
                for _ in 0..times {
                    lines.insert(i, lines[i].clone());
                }
            }
            5 if n > 1 => {
                let (i, j) = (self.pick(n), self.pick(n));
                lines.swap(i, j);
            }
            6 if n > 0 => {
                // A field dropped or doubled on one line.
                let i = self.pick(n);
                let mut fields: Vec<&str> = lines[i].split(',').collect();
                if fields.len() > 1 && self.rng.random_bool(0.5) {
                    fields.remove(self.pick(fields.len()));
                } else if !fields.is_empty() {
                    let k = self.pick(fields.len());
                    fields.insert(k, fields[k]);
                }
                lines[i] = fields.join(",");
            }
            7 if n > 0 => {
                let i = self.pick(n);
                lines[i] =
                    ["", "#", "[", "]]", "= 1", "\"", ",,,,", "\u{feff}"][self.pick(8)].into();
            }
            _ => return self.binary(b),
        }
        let mut out = lines.join("\n");
        if self.rng.random_bool(0.8) {
            out.push('\n');
        }
        *b = out.into_bytes();
    }

    fn binary(&mut self, b: &mut Vec<u8>) {
        let n = b.len();
        match self.rng.random_range(0..8) {
            0 if n > 0 => {
                let i = self.pick(n);
                b[i] ^= 1 << self.rng.random_range(0..8);
            }
            1 if n > 0 => {
                let i = self.pick(n);
                b[i] = [0u8, 1, 0x7F, 0x80, 0xFF][self.pick(5)];
            }
            2 if n >= 4 => {
                let i = self.pick(n - 3);
                let v = EXTREME_U32[self.pick(EXTREME_U32.len())];
                let bytes = if self.rng.random_bool(0.5) {
                    v.to_le_bytes()
                } else {
                    v.to_be_bytes()
                };
                b[i..i + 4].copy_from_slice(&bytes);
            }
            3 if n >= 8 => {
                let i = self.pick(n - 7);
                let v = [f64::NAN, f64::INFINITY, -1.0e300, 1.0e300, -0.0][self.pick(5)];
                if self.rng.random_bool(0.5) {
                    b[i..i + 8].copy_from_slice(&v.to_le_bytes());
                } else {
                    b[i..i + 4].copy_from_slice(&(v as f32).to_le_bytes());
                }
            }
            4 => b.truncate(self.pick(n + 1)),
            5 if n > 0 => {
                let s = self.pick(n);
                let e = (s + 1 + self.pick(64)).min(n);
                b.drain(s..e);
            }
            6 if n > 0 => {
                let s = self.pick(n);
                let e = (s + 1 + self.pick(256)).min(n);
                let chunk = b[s..e].to_vec();
                let at = self.pick(n + 1);
                b.splice(at..at, chunk);
            }
            _ => {
                let at = self.pick(n + 1);
                let k = 1 + self.pick(16);
                let junk: Vec<u8> = (0..k).map(|_| self.rng.random()).collect();
                b.splice(at..at, junk);
            }
        }
    }

    fn png(&mut self, b: &mut Vec<u8>) {
        let Some(chunks) = png_chunks(b) else {
            return self.binary(b);
        };
        if chunks.is_empty() || self.rng.random_bool(0.15) {
            return self.binary(b);
        }
        // IHDR (the first chunk) gets a third of the damage: that is where readers decide.
        let k = if self.rng.random_bool(0.33) {
            0
        } else {
            self.pick(chunks.len())
        };
        let (start, len) = chunks[k];
        let data = start + 8..start + 8 + len;
        match self.rng.random_range(0..4) {
            0 => {
                // Damage inside the chunk's data, keeping its length.
                let mut d = b[data.clone()].to_vec();
                let before = d.len();
                self.binary(&mut d);
                d.resize(before, 0);
                b[data.clone()].copy_from_slice(&d);
            }
            1 if chunks.len() > 1 => {
                b.drain(start..start + 12 + len);
                return;
            }
            2 => {
                let copy = b[start..start + 12 + len].to_vec();
                b.splice(start..start, copy);
                return;
            }
            _ if len >= 4 => {
                let i = data.start + self.pick(len - 3);
                let v = EXTREME_U32[self.pick(EXTREME_U32.len())];
                b[i..i + 4].copy_from_slice(&v.to_be_bytes());
            }
            _ => return self.binary(b),
        }
        let crc = crc32fast::hash(&b[start + 4..start + 8 + len]);
        b[start + 8 + len..start + 12 + len].copy_from_slice(&crc.to_be_bytes());
    }
}

/// Byte spans of the numbers in `text` (maximal runs of digits with sign, point and exponent).
fn number_spans(text: &str) -> Vec<(usize, usize)> {
    let bytes = text.as_bytes();
    let mut spans = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_digit() {
            let mut s = i;
            if s > 0 && bytes[s - 1] == b'-' {
                s -= 1;
            }
            let mut e = i;
            while e < bytes.len()
                && (bytes[e].is_ascii_digit()
                    || matches!(bytes[e], b'.' | b'e' | b'E' | b'+' | b'-'))
            {
                e += 1;
            }
            spans.push((s, e));
            i = e;
        } else {
            i += 1;
        }
    }
    spans
}

/// (start, data length) of every chunk of a PNG, or None when it is not one.
fn png_chunks(b: &[u8]) -> Option<Vec<(usize, usize)>> {
    const SIGNATURE: [u8; 8] = [0x89, b'P', b'N', b'G', 0x0D, 0x0A, 0x1A, 0x0A];
    if b.len() < 8 || b[..8] != SIGNATURE {
        return None;
    }
    let mut out = Vec::new();
    let mut at = 8;
    while at + 12 <= b.len() {
        let len = u32::from_be_bytes(b[at..at + 4].try_into().ok()?) as usize;
        if at + 12 + len > b.len() {
            break;
        }
        out.push((at, len));
        at += 12 + len;
    }
    Some(out)
}
