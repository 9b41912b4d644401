//! Parallel sums that give the same bits on every run: the items are cut
//! into chunks of a fixed size, the chunks are summed in parallel, and
//! their results are added in chunk order (floating-point addition does not
//! associate; rayon's `reduce` joins in whatever order work stealing
//! finishes). At most [`WAVE`] chunk results are held at once, so the
//! memory of a sum of large matrices stays bounded (collecting every
//! chunk's 0.7 MB normal matrix held 350 MB on the full sensor).

use rayon::prelude::*;

/// Chunk results computed in parallel before they are added in order.
pub const WAVE: usize = 32;

/// Pixels per chunk of the solvers' normal-equation sums: the additions
/// run on one thread, so a chunk must be large enough that they cost little
/// beside the work (128-pixel chunks of a 300-column normal matrix made the
/// joint stage 18 % slower than rayon's tree of additions), and small
/// enough for the cores (120 chunks on the full sensor's 61 000 pixels).
pub const SUM_CHUNK: usize = 512;

/// `add(…add(add(zero, f(c0)), f(c1))…)` over the chunks `c0, c1, …` of
/// `chunk` items of `items`, each `f` run in parallel, the additions in
/// chunk order: the same result, bit for bit, whatever the thread count.
pub fn chunk_sum<T, A, F, G>(items: &[T], chunk: usize, zero: A, f: F, add: G) -> A
where
    T: Sync,
    A: Send,
    F: Fn(&[T]) -> A + Sync,
    G: Fn(A, A) -> A,
{
    let chunk = chunk.max(1);
    let mut acc = zero;
    for wave in items.chunks(chunk * WAVE) {
        let parts: Vec<A> = wave.par_chunks(chunk).map(&f).collect();
        for part in parts {
            acc = add(acc, part);
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sum_is_the_sequential_one_in_chunk_order() {
        // Values whose sum depends on the order of addition.
        let v: Vec<f64> = (0..10_000)
            .map(|k: i32| (f64::from(k) * 0.37).sin() * 10f64.powi(k % 17 - 8))
            .collect();
        let want = v
            .chunks(7)
            .map(|c| c.iter().sum::<f64>())
            .fold(0.0, |a, b| a + b);
        for _ in 0..5 {
            let got = chunk_sum(&v, 7, 0.0, |c| c.iter().sum::<f64>(), |a, b| a + b);
            assert_eq!(got.to_bits(), want.to_bits());
        }
    }
}
