//! The order in which a dispatch's 8×8 tiles are handed to lavapipe's threads.
//!
//! llvmpipe splits a compute dispatch into one contiguous block of workgroups per thread
//! (Mesa's `lp_cs_tpool`: `iter_per_thread = num_iters / num_threads`, no stealing), so with
//! workgroups in image order one thread renders the top of the image and another the bottom,
//! and a dispatch lasts as long as its costlier half (a head's hair against its neck). The
//! integrator therefore visits tile rows in the order `row = workgroup_row × stride mod rows`,
//! a Weyl sequence with the stride near rows / φ: every run of consecutive workgroup rows spreads
//! over the whole image, whatever the thread count. A pixel's samples do not depend on which
//! workgroup renders it, so images are the same bit for bit. GPUs schedule workgroups
//! dynamically and keep image order (stride 1).

/// The tile-row stride for a dispatch of `rows` rows of workgroups: coprime with `rows` (so
/// the order is a permutation), near `rows × 0.618`.
pub fn tile_row_stride(rows: u32) -> u32 {
    if rows <= 2 {
        return 1;
    }
    let mut stride = ((u64::from(rows) * 618 + 500) / 1000).max(1) as u32;
    while gcd(stride, rows) != 1 {
        stride += 1;
    }
    stride
}

fn gcd(mut a: u32, mut b: u32) -> u32 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;

    fn order(rows: u32) -> Vec<u32> {
        let s = tile_row_stride(rows);
        (0..rows)
            .map(|r| ((u64::from(r) * u64::from(s)) % u64::from(rows)) as u32)
            .collect()
    }

    #[test]
    fn every_row_is_visited_once() {
        for rows in 1..=1024 {
            let mut seen = order(rows);
            seen.sort_unstable();
            assert_eq!(seen, (0..rows).collect::<Vec<_>>(), "{rows} rows");
        }
    }

    /// Whatever the thread count, each thread's block of consecutive workgroup rows takes rows
    /// from the whole image: its mean row is near the middle, and image order fails this.
    #[test]
    fn each_threads_block_spreads_over_the_image() {
        for rows in [8u32, 16, 32, 64, 128, 256, 512] {
            for threads in [2u32, 3, 4, 8, 16] {
                let block = rows / threads;
                if block < 4 {
                    continue;
                }
                let o = order(rows);
                for t in 0..threads as usize {
                    let part = &o[t * block as usize..(t + 1) * block as usize];
                    let mean = part.iter().map(|&r| f64::from(r)).sum::<f64>() / part.len() as f64;
                    let centre = f64::from(rows - 1) / 2.0;
                    assert!(
                        (mean - centre).abs() <= 0.2 * f64::from(rows),
                        "{rows} rows, {threads} threads, thread {t}: mean row {mean:.1}"
                    );
                }
            }
        }
        // Image order (stride 1) puts thread 0 in the top half: the check above would fail.
        let top: f64 = (0..16).map(f64::from).sum::<f64>() / 16.0;
        assert!((top - 15.5).abs() > 0.2 * 32.0);
    }
}
