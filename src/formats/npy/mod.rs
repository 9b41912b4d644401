//! NumPy `.npy` files (format 1.0 written; 1.0–3.0 read): little-endian,
//! C order, dtypes `|u1`, `<u2`, `<f8` and `|b1`. Stacks of camera frames
//! are written and read one frame at a time, never whole.

mod stack;

use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Write};

pub use stack::{NpyStackReader, NpyStackWriter};
use std::path::{Path, PathBuf};

const MAGIC: &[u8] = b"\x93NUMPY";

/// What went wrong with an NPY file.
#[derive(Debug, thiserror::Error)]
pub enum NpyError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// The header is not an NPY header we can read.
    #[error("{path}: not a readable .npy file: {problem}")]
    Header {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
    },
    /// The dtype or shape is not what the caller needs.
    #[error("{path}: expected {expected}, found {found}")]
    Unexpected {
        /// The file.
        path: PathBuf,
        /// What was expected.
        expected: String,
        /// What the file holds.
        found: String,
    },
    /// The data ends early.
    #[error("{path}: truncated: holds {complete} complete frames of {expected}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Frames (or elements, for plain arrays) present in full.
        complete: usize,
        /// Frames (or elements) the header announces.
        expected: usize,
    },
    /// A frame index beyond the stack.
    #[error("{path}: frame {frame} requested, the stack holds {frames}")]
    NoSuchFrame {
        /// The file.
        path: PathBuf,
        /// Requested frame.
        frame: usize,
        /// Frames in the stack.
        frames: usize,
    },
}

impl crate::outcome::Classify for NpyError {
    fn outcome(&self) -> Option<crate::outcome::Outcome> {
        use crate::outcome::Outcome;
        match self {
            NpyError::Io { source, .. } => crate::outcome::io_outcome(source),
            _ => Some(Outcome::Input),
        }
    }
}

/// Element types of camera frame stacks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StackDtype {
    /// `|u1`.
    U8,
    /// `<u2`.
    U16,
}

impl StackDtype {
    pub(crate) fn descr(self) -> &'static str {
        match self {
            StackDtype::U8 => "|u1",
            StackDtype::U16 => "<u2",
        }
    }

    pub(crate) fn size(self) -> usize {
        match self {
            StackDtype::U8 => 1,
            StackDtype::U16 => 2,
        }
    }
}

/// A parsed header.
#[derive(Debug, Clone, PartialEq)]
pub struct Header {
    /// dtype descriptor, e.g. `<f8`.
    pub descr: String,
    /// Array shape.
    pub shape: Vec<usize>,
    /// Byte offset of the data.
    pub data_offset: u64,
}

pub(crate) fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> NpyError + '_ {
    move |source| NpyError::Io {
        path: path.to_path_buf(),
        source,
    }
}

pub(crate) fn header_bytes(descr: &str, shape: &[usize]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_txt = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_txt}, }}");
    // Pad with spaces so magic + version + length + dict + '\n' is a multiple of 64.
    let total = MAGIC.len() + 2 + 2 + dict.len() + 1;
    dict.push_str(&" ".repeat((64 - total % 64) % 64));
    dict.push('\n');
    let mut out = MAGIC.to_vec();
    out.extend([1u8, 0u8]);
    out.extend((dict.len() as u16).to_le_bytes());
    out.extend(dict.as_bytes());
    out
}

/// The longest header this reader takes, bytes: NumPy's own `np.load`
/// refuses headers above 10 000 bytes (`max_header_size`) as unsafe; ours
/// are 128 bytes. Checked before the header is allocated.
const MAX_HEADER_LEN: usize = 10_000;

/// Reads and parses the header of an open NPY file.
fn read_header(path: &Path, r: &mut impl Read) -> Result<Header, NpyError> {
    let bad = |problem: String| NpyError::Header {
        path: path.to_path_buf(),
        problem,
    };
    let mut pre = [0u8; 8];
    r.read_exact(&mut pre)
        .map_err(|_| bad("shorter than the magic string".into()))?;
    if &pre[..6] != MAGIC {
        return Err(bad("bad magic string (not \\x93NUMPY)".into()));
    }
    let (len, prefix) = match pre[6] {
        1 => {
            let mut b = [0u8; 2];
            r.read_exact(&mut b).map_err(io_err(path))?;
            (u16::from_le_bytes(b) as usize, 10)
        }
        2 | 3 => {
            let mut b = [0u8; 4];
            r.read_exact(&mut b).map_err(io_err(path))?;
            (u32::from_le_bytes(b) as usize, 12)
        }
        v => return Err(bad(format!("unsupported format version {v}"))),
    };
    if len > MAX_HEADER_LEN {
        return Err(bad(format!(
            "header of {len} bytes announced: above the {MAX_HEADER_LEN} bytes a header may have"
        )));
    }
    let mut dict = vec![0u8; len];
    r.read_exact(&mut dict)
        .map_err(|_| bad("header shorter than announced".into()))?;
    let dict = String::from_utf8_lossy(&dict).to_string();
    let field = |key: &str| -> Result<String, NpyError> {
        let at = dict
            .find(&format!("'{key}'"))
            .ok_or_else(|| bad(format!("header has no '{key}'")))?;
        let rest = dict[at + key.len() + 2..]
            .trim_start()
            .trim_start_matches(':')
            .trim_start();
        Ok(rest.to_string())
    };
    let descr_rest = field("descr")?;
    let descr = descr_rest
        .trim_start_matches('\'')
        .split('\'')
        .next()
        .unwrap_or_default()
        .to_string();
    if field("fortran_order")?.starts_with("True") {
        return Err(bad(
            "Fortran order is not supported (expected C order)".into()
        ));
    }
    let shape_rest = field("shape")?;
    let inner = shape_rest
        .strip_prefix('(')
        .and_then(|s| s.split(')').next())
        .ok_or_else(|| bad(format!("unreadable shape {shape_rest}")))?;
    let shape = inner
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| {
            s.parse::<usize>()
                .map_err(|_| bad(format!("unreadable shape ({inner})")))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Header {
        descr,
        shape,
        data_offset: (prefix + len) as u64,
    })
}

/// The number of elements of `shape`, or an error when it overflows.
pub(crate) fn checked_len(path: &Path, shape: &[usize]) -> Result<usize, NpyError> {
    shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| NpyError::Header {
            path: path.to_path_buf(),
            problem: format!("shape {shape:?} has more elements than memory can address"),
        })
}

pub(crate) fn open_header(path: &Path) -> Result<(BufReader<File>, Header), NpyError> {
    let mut r = BufReader::new(File::open(path).map_err(io_err(path))?);
    let h = read_header(path, &mut r)?;
    Ok((r, h))
}

fn read_all(path: &Path, descr: &str, elem: usize) -> Result<(Vec<usize>, Vec<u8>), NpyError> {
    let (mut r, h) = open_header(path)?;
    if h.descr != descr {
        return Err(NpyError::Unexpected {
            path: path.to_path_buf(),
            expected: format!("dtype {descr}"),
            found: format!("dtype {}", h.descr),
        });
    }
    // The header's shape is checked against the file's length before
    // anything of its size is allocated: a corrupt header announcing 2^60
    // elements is an error, not an allocation.
    let n = checked_len(path, &h.shape)?;
    let available = std::fs::metadata(path)
        .map_err(io_err(path))?
        .len()
        .saturating_sub(h.data_offset);
    let needed = (n as u64).saturating_mul(elem as u64);
    if available < needed {
        return Err(NpyError::Truncated {
            path: path.to_path_buf(),
            complete: (available / elem as u64) as usize,
            expected: n,
        });
    }
    if available > needed {
        return Err(NpyError::Unexpected {
            path: path.to_path_buf(),
            expected: format!("{needed} bytes of data for shape {:?}", h.shape),
            found: format!("{available} bytes (data beyond the array)"),
        });
    }
    let mut data = Vec::with_capacity(needed as usize);
    r.read_to_end(&mut data).map_err(io_err(path))?;
    if data.len() as u64 != needed {
        return Err(NpyError::Truncated {
            path: path.to_path_buf(),
            complete: data.len() / elem,
            expected: n,
        });
    }
    Ok((h.shape, data))
}

/// Reads a float64 array: `(shape, values)`.
///
/// # Errors
/// [`NpyError`] naming the file, for I/O, header, dtype or length problems.
pub fn read_f64(path: &Path) -> Result<(Vec<usize>, Vec<f64>), NpyError> {
    let (shape, bytes) = read_all(path, "<f8", 8)?;
    let v = bytes
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().expect("8-byte chunk")))
        .collect();
    Ok((shape, v))
}

/// Reads a little-endian uint16 array (e.g. `flags.npy`): `(shape, values)`.
///
/// # Errors
/// [`NpyError`] naming the file, for I/O, header, dtype or length problems.
pub fn read_u16(path: &Path) -> Result<(Vec<usize>, Vec<u16>), NpyError> {
    let (shape, bytes) = read_all(path, "<u2", 2)?;
    let v = bytes
        .chunks_exact(2)
        .map(|c| u16::from_le_bytes([c[0], c[1]]))
        .collect();
    Ok((shape, v))
}

/// Reads a boolean array: `(shape, values)`.
///
/// # Errors
/// [`NpyError`] naming the file.
pub fn read_bool(path: &Path) -> Result<(Vec<usize>, Vec<bool>), NpyError> {
    let (shape, bytes) = read_all(path, "|b1", 1)?;
    Ok((shape, bytes.into_iter().map(|b| b != 0).collect()))
}

fn write_raw(path: &Path, descr: &str, shape: &[usize], data: &[u8]) -> Result<(), NpyError> {
    let mut w = BufWriter::new(File::create(path).map_err(io_err(path))?);
    w.write_all(&header_bytes(descr, shape))
        .map_err(io_err(path))?;
    w.write_all(data).map_err(io_err(path))?;
    w.flush().map_err(io_err(path))
}

fn check_shape(path: &Path, shape: &[usize], len: usize) -> Result<(), NpyError> {
    if shape.iter().product::<usize>() == len {
        return Ok(());
    }
    Err(NpyError::Unexpected {
        path: path.to_path_buf(),
        expected: format!(
            "{} values for shape {shape:?}",
            shape.iter().product::<usize>()
        ),
        found: format!("{len} values"),
    })
}

/// Writes a float64 array of `shape` (C order).
///
/// # Errors
/// [`NpyError`] when the shape does not match or the file cannot be written.
pub fn write_f64(path: &Path, shape: &[usize], data: &[f64]) -> Result<(), NpyError> {
    check_shape(path, shape, data.len())?;
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    write_raw(path, "<f8", shape, &bytes)
}

/// Writes a uint16 array of `shape` (C order).
///
/// # Errors
/// [`NpyError`] when the shape does not match or the file cannot be written.
pub fn write_u16(path: &Path, shape: &[usize], data: &[u16]) -> Result<(), NpyError> {
    check_shape(path, shape, data.len())?;
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
    write_raw(path, "<u2", shape, &bytes)
}

/// Writes a uint8 array of `shape` (C order).
///
/// # Errors
/// [`NpyError`] when the shape does not match or the file cannot be written.
pub fn write_u8(path: &Path, shape: &[usize], data: &[u8]) -> Result<(), NpyError> {
    check_shape(path, shape, data.len())?;
    write_raw(path, "|u1", shape, data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn header_is_64_byte_aligned() {
        for shape in [vec![3], vec![48, 48, 2, 2], vec![2000, 966, 1296]] {
            assert_eq!(header_bytes("<f8", &shape).len() % 64, 0);
        }
    }

    #[test]
    fn stack_round_trip_and_truncation() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("s.npy");
        let mut w = NpyStackWriter::create(&p, StackDtype::U16, 3, 2, 3).unwrap();
        w.append(&[1, 2, 3, 4, 5, 65535]).unwrap();
        w.append(&[7; 6]).unwrap();
        let err = w.finish().unwrap_err();
        assert!(matches!(
            err,
            NpyError::Truncated {
                complete: 2,
                expected: 3,
                ..
            }
        ));
        let mut r = NpyStackReader::open(&p).unwrap();
        assert_eq!((r.frames(), r.complete_frames()), (3, 2));
        let mut f = Vec::new();
        r.read_frame(0, &mut f).unwrap();
        assert_eq!(f, vec![1, 2, 3, 4, 5, 65535]);
        let err = r.read_frame(2, &mut f).unwrap_err().to_string();
        assert!(err.contains("2 complete frames of 3"), "{err}");
    }

    #[test]
    fn rejects_what_it_cannot_read() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npy");
        std::fs::write(&p, b"NOTNPY....").unwrap();
        assert!(read_f64(&p).unwrap_err().to_string().contains("magic"));
        let mut h = header_bytes("<f8", &[2]);
        let at = h.windows(5).position(|w| w == b"False").unwrap();
        h[at..at + 5].copy_from_slice(b"True ");
        std::fs::write(&p, &h).unwrap();
        assert!(read_f64(&p).unwrap_err().to_string().contains("Fortran"));
        write_u8(&p, &[2], &[1, 2]).unwrap();
        let err = read_f64(&p).unwrap_err().to_string();
        assert!(err.contains("<f8") && err.contains("|u1"), "{err}");
        std::fs::write(&p, header_bytes(">f8", &[1])).unwrap();
        assert!(read_f64(&p).is_err());
    }

    /// Regression (issue 19): a header announcing more elements than the
    /// file holds allocated them first ("capacity overflow" panic or an
    /// abort); a shape whose product overflows panicked in debug builds.
    #[test]
    fn header_sizes_are_checked_before_allocating() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npy");
        std::fs::write(&p, header_bytes("<f8", &[1 << 60])).unwrap();
        let err = read_f64(&p).unwrap_err().to_string();
        assert!(err.contains("truncated"), "{err}");
        std::fs::write(&p, header_bytes("<f8", &[1 << 40, 1 << 40])).unwrap();
        let err = read_f64(&p).unwrap_err().to_string();
        assert!(err.contains("more elements"), "{err}");
        std::fs::write(&p, header_bytes("<u2", &[1 << 32, 1 << 32, 1 << 32])).unwrap();
        let err = NpyStackReader::open(&p).unwrap_err().to_string();
        assert!(err.contains("more elements"), "{err}");
        // fuzz_readers: 0 frames of 2^40 × 2^40 pixels overflowed the frame size.
        std::fs::write(&p, header_bytes("<u2", &[0, 1 << 40, 1 << 40])).unwrap();
        let err = NpyStackReader::open(&p).unwrap_err().to_string();
        assert!(err.contains("more elements"), "{err}");
        std::fs::write(&p, header_bytes("<u2", &[3, 0, 4])).unwrap();
        assert!(NpyStackReader::open(&p).is_err());
        let mut h = header_bytes("<f8", &[1]);
        h[8..10].copy_from_slice(&u16::MAX.to_le_bytes());
        std::fs::write(&p, &h).unwrap();
        let err = read_f64(&p).unwrap_err().to_string();
        assert!(err.contains("10000 bytes"), "{err}");
    }

    /// An array with more data than its shape is an error, not truncated.
    #[test]
    fn data_beyond_the_shape_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.npy");
        write_f64(&p, &[3], &[1.0, 2.0, 3.0]).unwrap();
        let mut bytes = std::fs::read(&p).unwrap();
        bytes.extend(4.0f64.to_le_bytes());
        std::fs::write(&p, &bytes).unwrap();
        let err = read_f64(&p).unwrap_err().to_string();
        assert!(err.contains("beyond the array"), "{err}");
    }

    proptest! {
        #[test]
        fn f64_round_trip(shape in proptest::collection::vec(1usize..5, 1..5), seed in 0u64..1000) {
            let n: usize = shape.iter().product();
            let data: Vec<f64> = (0..n).map(|k| (k as f64 + seed as f64) * 1.37e-3 - 0.5).collect();
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("a.npy");
            write_f64(&p, &shape, &data).unwrap();
            let (s, d) = read_f64(&p).unwrap();
            prop_assert_eq!(s, shape);
            prop_assert_eq!(d, data);
        }
    }
}
