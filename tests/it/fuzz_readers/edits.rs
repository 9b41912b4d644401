//! The mutations the reader fuzzing applies: what kind of file is
//! mutated, the edits that make sense for it (lines, numbers, arrays,
//! truncation, bytes and words; NPY header fields; PNG chunks with their CRC
//! made right), as proptest strategies, and applying them to a base file.

use proptest::prelude::*;

/// What kind of file is mutated: the edits that make sense for it.
#[derive(Clone, Copy, Debug)]
pub(super) enum Kind {
    /// TOML or JSON: line and number edits as well as bytes.
    Text,
    /// NPY: header edits as well as bytes.
    Npy,
    /// PNG: chunk edits with the CRC made right again, as well as bytes.
    Png,
    /// TIFF and other binaries: bytes and words.
    Binary,
}

/// Values a number in a text file is replaced by.
pub(super) const NUMBERS: &[&str] = &[
    "nan",
    "inf",
    "-inf",
    "-0.0",
    "0",
    "1e308",
    "-1e308",
    "1e-320",
    "1e300",
    "-1",
    "-1.5",
    "4294967296",
    "18446744073709551616",
    "9223372036854775807",
    "65536",
    "4000000000",
    "1e9",
    "0.5",
];

/// dtypes an NPY header is given.
pub(super) const DTYPES: &[&str] = &[
    "<f8", "<u2", "|u1", "|b1", ">f8", "<f4", "<i8", "O", "<U10", "",
];

/// One edit; indices are taken modulo what they index.
#[derive(Clone, Debug)]
pub(super) enum Edit {
    DeleteLine(usize),
    DuplicateLine(usize),
    SwapLines(usize, usize),
    Number(usize, usize),
    GrowArray(usize),
    ShrinkArray(usize),
    Truncate(usize),
    FlipByte(usize, u8),
    Word(usize, u32),
    NpyShape(Vec<u64>),
    NpyDtype(usize),
    NpyFortran,
    NpyHeaderLen(u32),
    PngChunk(usize, usize, u32),
}

pub(super) fn edit(kind: Kind) -> BoxedStrategy<Edit> {
    let ix = any::<usize>();
    let bytes = prop_oneof![
        (ix, 1..8usize).prop_map(|(n, _)| Edit::Truncate(n)),
        (ix, any::<u8>()).prop_map(|(at, x)| Edit::FlipByte(at, x)),
        (
            ix,
            prop_oneof![
                Just(0u32),
                Just(u32::MAX),
                Just(0x7fff_ffff),
                Just(1 << 16),
                any::<u32>()
            ]
        )
            .prop_map(|(at, w)| Edit::Word(at, w)),
    ];
    match kind {
        Kind::Text => prop_oneof![
            1 => ix.prop_map(Edit::DeleteLine),
            1 => ix.prop_map(Edit::DuplicateLine),
            1 => (ix, ix).prop_map(|(a, b)| Edit::SwapLines(a, b)),
            4 => (ix, ix).prop_map(|(a, b)| Edit::Number(a, b)),
            1 => ix.prop_map(Edit::GrowArray),
            1 => ix.prop_map(Edit::ShrinkArray),
            1 => bytes,
        ]
        .boxed(),
        Kind::Npy => prop_oneof![
            2 => proptest::collection::vec(
                prop_oneof![0u64..6, Just(48), Just(1 << 31), Just(1 << 40), Just(u64::MAX)],
                0..5
            )
            .prop_map(Edit::NpyShape),
            1 => ix.prop_map(Edit::NpyDtype),
            1 => Just(Edit::NpyFortran),
            1 => prop_oneof![Just(0u32), Just(u16::MAX.into()), Just(u32::MAX), 0..200u32]
                .prop_map(Edit::NpyHeaderLen),
            2 => bytes,
        ]
        .boxed(),
        Kind::Png => prop_oneof![
            3 => (ix, ix, prop_oneof![Just(0u32), Just(u32::MAX), Just(1 << 20), Just(65_536), 0..64u32])
                .prop_map(|(c, at, w)| Edit::PngChunk(c, at, w)),
            2 => bytes,
        ]
        .boxed(),
        Kind::Binary => bytes.boxed(),
    }
}

pub(super) fn edits(kind: Kind) -> impl Strategy<Value = Vec<Edit>> {
    proptest::collection::vec(edit(kind), 1..4)
}

pub(super) fn apply(base: &[u8], edits: &[Edit]) -> Vec<u8> {
    let mut out = base.to_vec();
    for e in edits {
        out = apply_one(out, e);
    }
    out
}

pub(super) fn apply_one(mut b: Vec<u8>, e: &Edit) -> Vec<u8> {
    let lines =
        |b: &[u8]| -> Vec<Vec<u8>> { b.split(|&c| c == b'\n').map(<[u8]>::to_vec).collect() };
    let join = |l: Vec<Vec<u8>>| l.join(&b'\n');
    match *e {
        Edit::DeleteLine(k) => {
            let mut l = lines(&b);
            let k = k % l.len();
            l.remove(k);
            join(l)
        }
        Edit::DuplicateLine(k) => {
            let mut l = lines(&b);
            let k = k % l.len();
            let line = l[k].clone();
            l.insert(k, line);
            join(l)
        }
        Edit::SwapLines(i, j) => {
            let mut l = lines(&b);
            let n = l.len();
            l.swap(i % n, j % n);
            join(l)
        }
        Edit::Number(k, v) => {
            let spans = number_spans(&b);
            if spans.is_empty() {
                return b;
            }
            let (s, t) = spans[k % spans.len()];
            let mut out = b[..s].to_vec();
            out.extend(NUMBERS[v % NUMBERS.len()].as_bytes());
            out.extend(&b[t..]);
            out
        }
        Edit::GrowArray(k) | Edit::ShrinkArray(k) => {
            let closes: Vec<usize> = b
                .iter()
                .enumerate()
                .filter(|&(i, &c)| {
                    c == b']'
                        && i > 0
                        && b[..i]
                            .iter()
                            .rev()
                            .find(|c| !c.is_ascii_whitespace())
                            .is_some_and(u8::is_ascii_digit)
                })
                .map(|(i, _)| i)
                .collect();
            if closes.is_empty() {
                return b;
            }
            let at = closes[k % closes.len()];
            if matches!(e, Edit::GrowArray(_)) {
                b.splice(at..at, b", 1.0".iter().copied());
            } else if let Some(comma) = b[..at].iter().rposition(|&c| c == b',' || c == b'[') {
                if b[comma] == b',' {
                    b.drain(comma..at);
                }
            }
            b
        }
        Edit::Truncate(n) => {
            b.truncate(n % (b.len() + 1));
            b
        }
        Edit::FlipByte(at, x) => {
            if !b.is_empty() {
                let at = at % b.len();
                b[at] ^= x.max(1);
            }
            b
        }
        Edit::Word(at, w) => {
            if b.len() >= 4 {
                let at = at % (b.len() - 3);
                b[at..at + 4].copy_from_slice(&w.to_le_bytes());
            }
            b
        }
        Edit::NpyShape(ref shape) => {
            let dims: Vec<String> = shape.iter().map(u64::to_string).collect();
            let tuple = match dims.len() {
                1 => format!("({},)", dims[0]),
                _ => format!("({})", dims.join(", ")),
            };
            npy_dict_edit(b, "'shape': ", |rest| {
                let end = rest.find(')').map_or(rest.len(), |e| e + 1);
                format!("{tuple}{}", &rest[end..])
            })
        }
        Edit::NpyDtype(k) => npy_dict_edit(b, "'descr': '", |rest| {
            let end = rest.find('\'').unwrap_or(0);
            format!("{}{}", DTYPES[k % DTYPES.len()], &rest[end..])
        }),
        Edit::NpyFortran => npy_dict_edit(b, "'fortran_order': ", |rest| {
            format!("True{}", rest.strip_prefix("False").unwrap_or(rest))
        }),
        Edit::NpyHeaderLen(n) => {
            if b.len() >= 10 {
                let n = u16::try_from(n).unwrap_or(u16::MAX);
                b[8..10].copy_from_slice(&n.to_le_bytes());
            }
            b
        }
        Edit::PngChunk(c, at, w) => png_chunk_edit(b, c, at, w),
    }
}

/// Byte spans of the numbers in a text (a digit run with its sign,
/// fraction and exponent).
pub(super) fn number_spans(b: &[u8]) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let starts = b[i].is_ascii_digit()
            && (i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_'));
        if !starts {
            i += 1;
            continue;
        }
        let s = if i > 0 && b[i - 1] == b'-' { i - 1 } else { i };
        let mut t = i;
        while t < b.len() && (b[t].is_ascii_digit() || b"._eE+-".contains(&b[t])) {
            t += 1;
        }
        out.push((s, t));
        i = t;
    }
    out
}

/// Replaces the part of an NPY header dict after `key` by `f(rest)`, then
/// pads the dict to keep the header's announced length right.
pub(super) fn npy_dict_edit(b: Vec<u8>, key: &str, f: impl Fn(&str) -> String) -> Vec<u8> {
    if b.len() < 10 || !b.starts_with(b"\x93NUMPY") {
        return b;
    }
    let len = usize::from(u16::from_le_bytes([b[8], b[9]]));
    let end = (10 + len).min(b.len());
    let Ok(dict) = std::str::from_utf8(&b[10..end]) else {
        return b;
    };
    let Some(at) = dict.find(key) else {
        return b;
    };
    let head = &dict[..at + key.len()];
    let new = format!("{head}{}", f(&dict[at + key.len()..]));
    let mut new = new.trim_end().to_string();
    // Keep the header 64-byte aligned, as writers do; a longer dict grows it.
    while (10 + new.len() + 1) % 64 != 0 {
        new.push(' ');
    }
    new.push('\n');
    let mut out = b[..8].to_vec();
    out.extend(u16::try_from(new.len()).unwrap_or(u16::MAX).to_le_bytes());
    out.extend(new.as_bytes());
    out.extend(&b[end..]);
    out
}

/// Overwrites a big-endian word inside chunk `c`'s data (IHDR's width,
/// height, depth, ...) and recomputes that chunk's CRC.
pub(super) fn png_chunk_edit(mut b: Vec<u8>, c: usize, at: usize, w: u32) -> Vec<u8> {
    let mut chunks = Vec::new();
    let mut pos = 8;
    while pos + 12 <= b.len() {
        let len = u32::from_be_bytes([b[pos], b[pos + 1], b[pos + 2], b[pos + 3]]) as usize;
        if pos + 12 + len > b.len() {
            break;
        }
        chunks.push((pos, len));
        pos += 12 + len;
    }
    if chunks.is_empty() {
        return b;
    }
    let (pos, len) = chunks[c % chunks.len()];
    if len >= 4 {
        let at = pos + 8 + (at % (len - 3));
        b[at..at + 4].copy_from_slice(&w.to_be_bytes());
    } else if len > 0 {
        b[pos + 8] = w as u8;
    }
    let crc = crc32fast::hash(&b[pos + 4..pos + 8 + len]);
    b[pos + 8 + len..pos + 12 + len].copy_from_slice(&crc.to_be_bytes());
    b
}
