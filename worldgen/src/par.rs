//! Row-parallel helpers on scoped std threads. Work is split by rows and every row is computed
//! independently, so results are identical for any thread count (a determinism requirement).

/// The worker count to use: `requested` if non-zero, else the machine's available parallelism.
pub fn thread_count(requested: usize) -> usize {
    if requested > 0 {
        requested
    } else {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    }
}

/// Calls `f(y, row)` for every row of `data` (rows of `width` items), on `threads` threads.
/// `on_rows_done(n)` is called after each band of rows (for progress bars).
pub fn for_each_row<T: Send>(
    data: &mut [T],
    width: usize,
    threads: usize,
    f: impl Fn(usize, &mut [T]) + Sync,
    on_rows_done: &(dyn Fn(u64) + Sync),
) {
    let width = width.max(1);
    let rows = data.len() / width;
    if rows == 0 {
        return;
    }
    let threads = threads.clamp(1, rows);
    // Bands of a few rows keep the progress bar smooth; the band size does not affect results.
    let band_rows = 16usize;
    let next = std::sync::atomic::AtomicUsize::new(0);
    let bands: Vec<std::sync::Mutex<Option<&mut [T]>>> = data
        .chunks_mut(band_rows * width)
        .map(|c| std::sync::Mutex::new(Some(c)))
        .collect();
    std::thread::scope(|scope| {
        for _ in 0..threads {
            scope.spawn(|| {
                loop {
                    let band = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if band >= bands.len() {
                        break;
                    }
                    // Each band is taken exactly once (the counter hands out each index once).
                    let chunk = bands[band].lock().map(|mut g| g.take()).ok().flatten();
                    let Some(chunk) = chunk else { continue };
                    let n = chunk.len() / width;
                    for (i, row) in chunk.chunks_exact_mut(width).enumerate() {
                        f(band * band_rows + i, row);
                    }
                    on_rows_done(n as u64);
                }
            });
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_row_is_visited_once_with_its_index() {
        for threads in [1, 2, 5] {
            let mut data = vec![0usize; 7 * 100];
            for_each_row(
                &mut data,
                7,
                threads,
                |y, row| row.iter_mut().for_each(|v| *v += y + 1),
                &|_| {},
            );
            for (i, v) in data.iter().enumerate() {
                assert_eq!(*v, i / 7 + 1);
            }
        }
    }
}
