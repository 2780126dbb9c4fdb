//! Writing big files (cache objects, staged outputs): in pieces side by side, and around the
//! page cache where the filesystem allows it.
//!
//! Every file written here is fsynced before it is renamed into place, so its bytes reach the
//! disk before texsyn goes on whichever way they are written. Written through the page cache
//! they are first copied into freshly allocated pages, and on the virtual machines texsyn is
//! measured on that copy was the slowest step of a million-triangle export: `dd` of 512 MB
//! took 2.4 s buffered into fresh pages (all of it system time) and 0.45 s with `O_DIRECT`
//! (0.1 s of CPU); a 1.4M-triangle jump-maps run writes 640 MB (its 330 MB export bundle and
//! 307 MB of outputs), about 1.5 s of which was spent in that copy with both cores busy.
//! So on Linux the whole 4 KiB blocks of a big file are written with `O_DIRECT` (from a
//! reused aligned buffer when the bytes are not aligned), and the rest (the last partial
//! block, or a piece the filesystem refused) through the page cache. A filesystem without
//! direct I/O (tmpfs) refuses the flag and everything goes through the page cache, as it does
//! on other systems. The file's bytes are the same either way.

use std::fs::File;
use std::io::Write;

/// Pieces of a big file written side by side (a million-triangle export's bundle is over
/// 100 MB). A multiple of [`BLOCK`].
const WRITE_PIECE: usize = 16 << 20;

/// The alignment direct I/O needs of offsets, lengths and memory (the largest logical block
/// size of common disks).
#[cfg(target_os = "linux")]
const BLOCK: usize = 4096;

/// Writes `bytes` to the empty file `f`, big ones in [`WRITE_PIECE`]s in parallel (Unix;
/// elsewhere in one piece). The file's bytes are the same either way. Only for a temporary
/// file that is renamed into place after `sync_all`: the file gets its full length first, so
/// a failed or interrupted write leaves holes of zeros, not a short file. The error is the
/// first failed piece's, whatever the thread count.
pub(crate) fn write_parallel(f: &File, bytes: &[u8]) -> std::io::Result<()> {
    #[cfg(unix)]
    if bytes.len() > WRITE_PIECE {
        use rayon::prelude::*;
        use std::os::unix::fs::FileExt;
        f.set_len(bytes.len() as u64)?;
        // Which pieces the direct pass wrote whole; the rest (and the last partial block) go
        // through the page cache after it, since the flag is the open file's, not a write's.
        #[cfg(target_os = "linux")]
        let (direct_end, done) = direct::write_blocks(f, bytes);
        #[cfg(not(target_os = "linux"))]
        let (direct_end, done) = (0usize, Vec::<bool>::new());
        let results: Vec<std::io::Result<()>> = bytes
            .par_chunks(WRITE_PIECE)
            .enumerate()
            .map(|(i, piece)| {
                let offset = i * WRITE_PIECE;
                let skip = if done.get(i).copied().unwrap_or(false) {
                    direct_end.saturating_sub(offset).min(piece.len())
                } else {
                    0
                };
                match &piece[skip..] {
                    [] => Ok(()),
                    rest => f.write_all_at(rest, (offset + skip) as u64),
                }
            })
            .collect();
        return results.into_iter().collect();
    }
    let mut f = f;
    f.write_all(bytes)
}

#[cfg(target_os = "linux")]
mod direct {
    use super::{BLOCK, WRITE_PIECE};
    use rayon::prelude::*;
    use std::cell::RefCell;
    use std::fs::File;
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::FileExt;

    #[derive(Clone, Copy)]
    #[repr(C, align(4096))]
    struct Block([u8; BLOCK]);

    thread_local! {
        /// One piece's worth of aligned memory per thread, kept for the process's life:
        /// allocating it per piece would touch fresh pages again, which is what direct
        /// writing avoids.
        static BOUNCE: RefCell<Vec<Block>> = const { RefCell::new(Vec::new()) };
    }

    /// Sets or clears `O_DIRECT` on `f`'s open file; false if refused.
    fn set_direct(f: &File, on: bool) -> bool {
        let fd = f.as_raw_fd();
        // Safety: fcntl on a descriptor `f` owns, with flag arguments only.
        unsafe {
            let flags = libc::fcntl(fd, libc::F_GETFL);
            if flags < 0 {
                return false;
            }
            let want = if on {
                flags | libc::O_DIRECT
            } else {
                flags & !libc::O_DIRECT
            };
            libc::fcntl(fd, libc::F_SETFL, want) == 0
        }
    }

    /// Writes the whole blocks of `bytes` with `O_DIRECT`, a piece per task; returns where
    /// the whole blocks end and which pieces were written (a piece the filesystem refused is
    /// left to the buffered pass). `O_DIRECT` is cleared again before returning (if it cannot
    /// be, no piece counts as written and the buffered pass writes everything again).
    pub(super) fn write_blocks(f: &File, bytes: &[u8]) -> (usize, Vec<bool>) {
        let end = bytes.len() / BLOCK * BLOCK;
        if end == 0 || !set_direct(f, true) {
            return (0, Vec::new());
        }
        let done: Vec<bool> = bytes[..end]
            .par_chunks(WRITE_PIECE)
            .enumerate()
            .map(|(i, piece)| write_aligned(f, piece, (i * WRITE_PIECE) as u64).is_ok())
            .collect();
        if !set_direct(f, false) {
            return (0, Vec::new());
        }
        (end, done)
    }

    /// One piece (whole blocks, at a block offset), from `piece` itself when it is aligned
    /// in memory, else through this thread's aligned buffer.
    fn write_aligned(f: &File, piece: &[u8], offset: u64) -> std::io::Result<()> {
        if (piece.as_ptr() as usize).is_multiple_of(BLOCK) {
            return f.write_all_at(piece, offset);
        }
        BOUNCE.with(|b| {
            let mut b = b.borrow_mut();
            if b.len() < WRITE_PIECE / BLOCK {
                *b = vec![Block([0; BLOCK]); WRITE_PIECE / BLOCK];
            }
            // Safety: `Block` is a plain byte array, so the vector is `len * BLOCK`
            // initialized bytes, aligned to `BLOCK`.
            let buf: &mut [u8] = unsafe {
                std::slice::from_raw_parts_mut(b.as_mut_ptr().cast::<u8>(), b.len() * BLOCK)
            };
            let buf = &mut buf[..piece.len()];
            buf.copy_from_slice(piece);
            f.write_all_at(buf, offset)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bytes that differ at every position of a piece and between pieces.
    fn pattern(len: usize) -> Vec<u8> {
        (0..len)
            .map(|i| (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15).to_le_bytes()[7])
            .collect()
    }

    fn round_trip(bytes: &[u8]) {
        let dir = crate::pipeline::outputs::TempDir::create("texsyn-big-write").unwrap();
        let path = dir.path().join("f");
        let f = File::create(&path).unwrap();
        write_parallel(&f, bytes).unwrap();
        f.sync_all().unwrap();
        drop(f);
        let back = std::fs::read(&path).unwrap();
        assert_eq!(back.len(), bytes.len());
        assert!(
            back == bytes,
            "the file's bytes differ from what was written"
        );
    }

    #[test]
    fn big_files_come_back_byte_for_byte_whatever_their_alignment_and_tail() {
        // Several pieces, a last piece that is not whole blocks, a tail shorter than a block.
        let bytes = pattern(2 * WRITE_PIECE + 3 * 4096 + 123);
        round_trip(&bytes);
        // The same bytes starting off any block boundary in memory (the bounce buffer).
        let shifted = [&[0u8; 7][..], &bytes].concat();
        round_trip(&shifted[7..]);
        // Whole blocks only, and a file one byte over one piece.
        round_trip(&pattern(WRITE_PIECE + 4096));
        round_trip(&pattern(WRITE_PIECE + 1));
    }

    #[test]
    fn small_files_are_written_whole() {
        round_trip(&pattern(5000));
        round_trip(&[]);
    }
}
