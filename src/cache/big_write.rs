//! Writing big files (cache objects, staged outputs): in pieces side by side, and around the
//! page cache where the filesystem allows it.
//!
//! Every file written here is fsynced before it is renamed into place, so its bytes reach the
//! disk before texsyn goes on whichever way they are written. Written through the page cache
//! they are first copied into freshly allocated pages, and on the virtual machines texsyn is
//! measured on that copy was the slowest step of a million-triangle export: `dd` of 512 MB
//! took 2.4 s buffered into fresh pages (all of it system time) and 0.45 s with `O_DIRECT`
//! (0.1 s of CPU); a 1.4M-triangle jump-maps run writes 640 MB (its 330 MB export bundle and
//! 307 MB of outputs), and that copy took about 2.2 s of its CPU (BENCHMARKS.md, the jump
//! maps' fifth pass). So on Linux the whole 4 KiB blocks of a big file are written with
//! `O_DIRECT` (through a small reused aligned buffer when the bytes are not aligned in
//! memory), and the rest (the last partial block, or a piece the filesystem refused) through
//! the page cache. tmpfs is left out (its direct I/O, where it has any, still copies into the
//! page cache, which is where its files live), as is every other system. The file's bytes
//! are the same either way.
//!
//! The cost: after a cold run the files are not in the page cache, so what reads them next
//! (the first rerun comparing the outputs with what it would write, a viewer) reads them from
//! the disk once.

use std::fs::File;
use std::io::Write;

/// Pieces of a big file written side by side (a million-triangle export's bundle is over
/// 100 MB). A multiple of the direct-I/O block (4 KiB).
const WRITE_PIECE: usize = 16 << 20;

/// How a big write went: bytes written with direct I/O, and pieces the direct pass tried but
/// the filesystem refused (written through the page cache instead).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
pub(crate) struct BigWrite {
    pub direct_bytes: usize,
    pub refused_pieces: usize,
}

/// Writes `bytes` to the empty file `f`, big ones in [`WRITE_PIECE`]s in parallel (Unix;
/// elsewhere in one piece). The file's bytes are the same either way. Only for a temporary
/// file that is renamed into place after `sync_all`: the file gets its full length first, so
/// a failed or interrupted write leaves holes of zeros, not a short file. The error is the
/// first failed piece's, whatever the thread count.
pub(crate) fn write_parallel(f: &File, bytes: &[u8]) -> std::io::Result<()> {
    write_reporting(f, bytes).map(|_| ())
}

/// [`write_parallel`], saying how the bytes went.
pub(crate) fn write_reporting(f: &File, bytes: &[u8]) -> std::io::Result<BigWrite> {
    #[cfg(unix)]
    if bytes.len() > WRITE_PIECE {
        use rayon::prelude::*;
        use std::os::unix::fs::FileExt;
        f.set_len(bytes.len() as u64)?;
        // Which pieces the direct pass wrote whole; the rest (and the last partial block) go
        // through the page cache after it, since the flag is the open file's, not a write's.
        #[cfg(target_os = "linux")]
        let (direct_end, done) = direct::write_blocks(f, bytes)?;
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
        results.into_iter().collect::<std::io::Result<()>>()?;
        let whole = done.iter().filter(|&&d| d).count();
        let report = BigWrite {
            // Every piece but the last is whole blocks; the last one's blocks end at
            // `direct_end`.
            direct_bytes: (0..done.len())
                .filter(|&i| done[i])
                .map(|i| direct_end.saturating_sub(i * WRITE_PIECE).min(WRITE_PIECE))
                .sum(),
            refused_pieces: done.len() - whole,
        };
        if report.refused_pieces > 0 {
            tracing::debug!(
                "{} of {} pieces refused direct I/O, written through the page cache",
                report.refused_pieces,
                done.len()
            );
        }
        return Ok(report);
    }
    let mut f = f;
    f.write_all(bytes)?;
    Ok(BigWrite::default())
}

#[cfg(target_os = "linux")]
mod direct {
    use super::WRITE_PIECE;
    use rayon::prelude::*;
    use std::cell::RefCell;
    use std::fs::File;
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::FileExt;

    /// The alignment direct I/O needs of offsets, lengths and memory (the largest logical
    /// block size of common disks).
    pub(super) const BLOCK: usize = 4096;
    /// The aligned buffer unaligned bytes go through, a piece at a time in steps of this.
    const BOUNCE: usize = 1 << 20;

    #[derive(Clone, Copy)]
    #[repr(C, align(4096))]
    pub(super) struct Block(pub [u8; BLOCK]);

    thread_local! {
        /// One step's worth of aligned memory per thread, kept for the process's life:
        /// allocating it per step would touch fresh pages again, which is what direct
        /// writing avoids.
        static BOUNCE_BUF: RefCell<Vec<Block>> = const { RefCell::new(Vec::new()) };
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

    /// Whether `f` is on tmpfs (whose files live in the page cache anyway).
    #[allow(clippy::unnecessary_cast)] // `f_type`'s type and the constant's differ by platform
    fn on_tmpfs(f: &File) -> bool {
        // Safety: fstatfs fills the zeroed struct it is given, for a descriptor `f` owns.
        unsafe {
            let mut s: libc::statfs = std::mem::zeroed();
            libc::fstatfs(f.as_raw_fd(), &mut s) == 0 && s.f_type as i64 == libc::TMPFS_MAGIC as i64
        }
    }

    /// Writes the whole blocks of `bytes` with `O_DIRECT`, a piece per task; returns where
    /// the whole blocks end and which pieces were written (a piece the filesystem refused is
    /// left to the buffered pass; none are tried where the flag is refused or on tmpfs).
    /// `O_DIRECT` is cleared again before returning; if it cannot be, that is the error.
    pub(super) fn write_blocks(f: &File, bytes: &[u8]) -> std::io::Result<(usize, Vec<bool>)> {
        let end = bytes.len() / BLOCK * BLOCK;
        if end == 0 || on_tmpfs(f) || !set_direct(f, true) {
            return Ok((0, Vec::new()));
        }
        let done: Vec<bool> = bytes[..end]
            .par_chunks(WRITE_PIECE)
            .enumerate()
            .map(|(i, piece)| write_aligned(f, piece, (i * WRITE_PIECE) as u64).is_ok())
            .collect();
        if !set_direct(f, false) {
            return Err(std::io::Error::last_os_error());
        }
        Ok((end, done))
    }

    /// One piece (whole blocks, at a block offset), from `piece` itself when it is aligned
    /// in memory, else through this thread's aligned buffer.
    fn write_aligned(f: &File, piece: &[u8], offset: u64) -> std::io::Result<()> {
        if (piece.as_ptr() as usize).is_multiple_of(BLOCK) {
            return f.write_all_at(piece, offset);
        }
        BOUNCE_BUF.with(|b| {
            let mut b = b.borrow_mut();
            if b.len() < BOUNCE / BLOCK {
                *b = vec![Block([0; BLOCK]); BOUNCE / BLOCK];
            }
            // Safety: `Block` is a plain byte array, so the vector is `len * BLOCK`
            // initialized bytes, aligned to `BLOCK`.
            let buf: &mut [u8] = unsafe {
                std::slice::from_raw_parts_mut(b.as_mut_ptr().cast::<u8>(), b.len() * BLOCK)
            };
            for (k, step) in piece.chunks(BOUNCE).enumerate() {
                let buf = &mut buf[..step.len()];
                buf.copy_from_slice(step);
                f.write_all_at(buf, offset + (k * BOUNCE) as u64)?;
            }
            Ok(())
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

    /// Writes `bytes` into a fresh file beside the test binary (on the build's disk, not in
    /// the system's temporary folder, which may be tmpfs) and checks them back.
    fn round_trip(bytes: &[u8]) -> BigWrite {
        let exe = std::env::current_exe().unwrap();
        let dir = exe.parent().unwrap();
        let path = dir.join(format!(
            "big-write-{}-{}",
            std::process::id(),
            bytes.len() ^ (bytes.as_ptr() as usize)
        ));
        let f = File::create(&path).unwrap();
        let report = write_reporting(&f, bytes).unwrap();
        f.sync_all().unwrap();
        drop(f);
        let back = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        assert_eq!(back.len(), bytes.len());
        assert!(
            back == bytes,
            "the file's bytes differ from what was written"
        );
        report
    }

    #[test]
    fn big_files_come_back_byte_for_byte_whatever_their_alignment_and_tail() {
        // Several pieces, a last piece that is not whole blocks, a tail shorter than a block:
        // from memory that is not block-aligned (the bounce buffer) ...
        let len = 2 * WRITE_PIECE + 3 * 4096 + 123;
        let bytes = pattern(len);
        let shifted = [&[0u8; 7][..], &bytes].concat();
        let unaligned = round_trip(&shifted[7..]);
        // ... and from block-aligned memory (written as it is).
        #[cfg(target_os = "linux")]
        {
            let mut blocks = vec![direct::Block([0; direct::BLOCK]); len.div_ceil(direct::BLOCK)];
            // Safety: plain bytes, as in the writer.
            let raw: &mut [u8] = unsafe {
                std::slice::from_raw_parts_mut(
                    blocks.as_mut_ptr().cast::<u8>(),
                    blocks.len() * direct::BLOCK,
                )
            };
            raw[..len].copy_from_slice(&bytes);
            let aligned = round_trip(&raw[..len]);
            // Where the filesystem takes direct I/O at all, every whole block went that way,
            // whichever way the bytes were aligned in memory.
            for report in [unaligned, aligned] {
                if report.direct_bytes > 0 {
                    assert_eq!(report.refused_pieces, 0);
                    assert_eq!(report.direct_bytes, len / direct::BLOCK * direct::BLOCK);
                }
            }
        }
        let _ = unaligned;
        // Whole blocks only, and a file one byte over one piece.
        round_trip(&pattern(WRITE_PIECE + 4096));
        round_trip(&pattern(WRITE_PIECE + 1));
    }

    #[test]
    fn small_files_are_written_whole() {
        assert_eq!(round_trip(&pattern(5000)), BigWrite::default());
        assert_eq!(round_trip(&[]), BigWrite::default());
    }
}
