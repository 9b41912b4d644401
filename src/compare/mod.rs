//! Comparison with an interferometer: Fizeau height maps (Zygo MetroPro `.dat`, Zygo `.datx`, NPY/CSV), registration on the measured aperture, the same Zernike fit, and the difference.
