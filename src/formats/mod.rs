//! File formats at the program's edges that are not tied to one stage:
//! NumPy arrays ([`npy`]), camera frames as PNG/TIFF ([`image_io`]) and the
//! reconstructed surfaces (`surfaces.json`, [`surfaces_file`]). The station
//! file lives with the station ([`crate::optics::station`]), the acquisition
//! manifest with the acquisition ([`crate::acquire::acquisition`]).

pub mod image_io;
pub mod npy;
pub mod surfaces_file;
