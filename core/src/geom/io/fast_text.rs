//! What the fast paths of the text readers share: the file cut into pieces of whole lines that
//! are read in parallel, a tokenizer over one line's bytes, and number parsing without
//! allocation.
//!
//! A fast path reads a well-formed file straight into the mesh and declines (returns `None`)
//! at the first thing it does not expect; the reference reader then reads the file again and
//! gives the error (or, for a valid file laid out unusually, the mesh). So every error is
//! exactly the reference reader's, and a fast path only has to get valid files right: the tests
//! compare both on every input they make.
//!
//! Parallel reading is deterministic: a file is cut at line ends into pieces of a fixed size
//! (not a fixed number, so the cut does not depend on the thread count either), a first pass
//! counts each piece's records, their prefix sums say which record each piece starts at, and
//! the second pass's results are concatenated in file order.

use rayon::prelude::*;

/// Bytes per piece: big enough that a piece's overhead vanishes, small enough that two cores
/// share a 50 MB file evenly.
const PIECE: usize = 1 << 20;

/// `bytes` cut into pieces of about [`PIECE`] bytes, each ending just after a `\n` (the last
/// at the end of `bytes`).
pub(super) fn pieces(bytes: &[u8]) -> Vec<&[u8]> {
    let mut out = Vec::with_capacity(bytes.len() / PIECE + 1);
    let mut rest = bytes;
    while rest.len() > PIECE {
        let cut = match memchr::memchr(b'\n', &rest[PIECE..]) {
            Some(p) => PIECE + p + 1,
            None => rest.len(),
        };
        let (piece, tail) = rest.split_at(cut);
        out.push(piece);
        rest = tail;
    }
    if !rest.is_empty() {
        out.push(rest);
    }
    out
}

/// `f` applied to each piece, in parallel when there is more than one; results in file order.
pub(super) fn map_pieces<'a, T: Send>(
    pieces: &[&'a [u8]],
    f: impl Fn(usize, &'a [u8]) -> T + Sync + Send,
) -> Vec<T> {
    if pieces.len() <= 1 {
        pieces.iter().enumerate().map(|(i, p)| f(i, p)).collect()
    } else {
        pieces
            .par_iter()
            .enumerate()
            .map(|(i, p)| f(i, p))
            .collect()
    }
}

/// The index of each piece's first record, from the records each piece holds (an exclusive
/// prefix sum), so pieces parsed in parallel know where they start.
pub(super) fn firsts(counts: &[usize]) -> Vec<usize> {
    counts
        .iter()
        .scan(0, |acc, &c| {
            let first = *acc;
            *acc += c;
            Some(first)
        })
        .collect()
}

/// The lines of `bytes` (split at `\n`, the `\n` not included).
pub(super) fn lines(bytes: &[u8]) -> impl Iterator<Item = &[u8]> {
    let mut rest = Some(bytes);
    std::iter::from_fn(move || {
        let r = rest?;
        match memchr::memchr(b'\n', r) {
            Some(p) => {
                rest = Some(&r[p + 1..]);
                Some(&r[..p])
            }
            None => {
                rest = None;
                (!r.is_empty()).then_some(r)
            }
        }
    })
}

/// Whitespace-separated tokens of one line, as the reference readers split them: `COMMENTS`
/// makes `#` end the line (OFF, OBJ); PLY bodies have no comments.
pub(super) struct Tokens<'a, const COMMENTS: bool> {
    line: &'a [u8],
    pos: usize,
}

impl<'a, const COMMENTS: bool> Tokens<'a, COMMENTS> {
    pub(super) fn new(line: &'a [u8]) -> Self {
        Tokens { line, pos: 0 }
    }

    /// Whether the line has no (more) tokens.
    pub(super) fn is_done(&mut self) -> bool {
        self.skip_space();
        self.pos >= self.line.len() || (COMMENTS && self.line[self.pos] == b'#')
    }

    fn skip_space(&mut self) {
        while self
            .line
            .get(self.pos)
            .is_some_and(|b| b.is_ascii_whitespace())
        {
            self.pos += 1;
        }
    }
}

impl<'a, const COMMENTS: bool> Iterator for Tokens<'a, COMMENTS> {
    type Item = &'a [u8];

    #[inline]
    fn next(&mut self) -> Option<&'a [u8]> {
        if self.is_done() {
            self.pos = self.line.len();
            return None;
        }
        let start = self.pos;
        while let Some(&b) = self.line.get(self.pos) {
            if b.is_ascii_whitespace() || (COMMENTS && b == b'#') {
                break;
            }
            self.pos += 1;
        }
        Some(&self.line[start..self.pos])
    }
}

/// `token` as a `usize`, exactly as `str::parse::<usize>` reads it (digits are read here, any
/// other form by the standard parser).
#[inline]
pub(super) fn parse_usize(token: &[u8]) -> Option<usize> {
    if !token.is_empty() && token.len() <= 19 && token.iter().all(u8::is_ascii_digit) {
        return Some(
            token
                .iter()
                .fold(0usize, |n, &d| n * 10 + usize::from(d - b'0')),
        );
    }
    super::parse(token)
}

/// `token` as an `i64`, exactly as `str::parse::<i64>` reads it.
#[inline]
pub(super) fn parse_i64(token: &[u8]) -> Option<i64> {
    let (negative, digits) = match token.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, token),
    };
    if !digits.is_empty() && digits.len() <= 18 && digits.iter().all(u8::is_ascii_digit) {
        let n = digits
            .iter()
            .fold(0i64, |n, &d| n * 10 + i64::from(d - b'0'));
        return Some(if negative { -n } else { n });
    }
    super::parse(token)
}

/// A finite coordinate, as [`super::coord`] accepts it (the standard library's correctly
/// rounded parser, straight to f32), or `None`.
#[inline]
pub(super) fn coord(token: &[u8]) -> Option<f32> {
    parse_f32(token).filter(|x| x.is_finite())
}

/// `token` as `str::parse::<f32>` reads it (correctly rounded, NaN and infinities included).
#[inline]
pub(super) fn parse_f32(token: &[u8]) -> Option<f32> {
    // Numbers are ASCII, so anything else fails the standard parser too; checking that is
    // cheaper than a UTF-8 validation per token.
    if !token.is_ascii() {
        return None;
    }
    // SAFETY: ASCII is valid UTF-8.
    let text = unsafe { std::str::from_utf8_unchecked(token) };
    text.parse::<f32>().ok()
}

/// Fan-triangulates `corners` onto `triangles`, a triangle without the loop.
#[inline]
pub(super) fn fan(corners: &[u32], triangles: &mut Vec<[u32; 3]>) {
    match *corners {
        [a, b, c] => triangles.push([a, b, c]),
        _ => super::fan(corners, triangles),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_end_at_line_ends_and_cover_the_file() {
        let line = b"0.125 -3 7\n";
        let bytes: Vec<u8> = line
            .iter()
            .copied()
            .cycle()
            .take(line.len() * 300_000)
            .collect();
        let p = pieces(&bytes);
        assert!(p.len() > 2);
        assert_eq!(p.concat(), bytes);
        assert!(p.iter().all(|p| p.ends_with(b"\n")));
        assert_eq!(pieces(b"no newline"), vec![&b"no newline"[..]]);
        assert!(pieces(b"").is_empty());
    }

    #[test]
    fn tokens_split_like_the_reference_tokenizer() {
        for line in [
            &b"  v 1 2\t3 "[..],
            b"a#b c",
            b"#only",
            b"",
            b"x\ry\x0cz",
            b"f 1/2/3 4//5 -1 # comment 9",
        ] {
            let stripped = match line.iter().position(|&b| b == b'#') {
                Some(p) => &line[..p],
                None => line,
            };
            let want: Vec<&[u8]> = super::super::tokens(stripped).collect();
            assert_eq!(Tokens::<true>::new(line).collect::<Vec<_>>(), want);
            let want: Vec<&[u8]> = super::super::tokens(line).collect();
            assert_eq!(Tokens::<false>::new(line).collect::<Vec<_>>(), want);
        }
    }

    #[test]
    fn integers_parse_as_the_standard_parser_does() {
        for t in [
            "0",
            "7",
            "+7",
            "-7",
            "-0",
            "007",
            "18446744073709551615",
            "18446744073709551616",
            "9223372036854775807",
            "9223372036854775808",
            "-9223372036854775808",
            "999999999999999999",
            "1.0",
            "",
            "-",
            "1e3",
            " 1",
        ] {
            assert_eq!(parse_usize(t.as_bytes()), t.parse().ok(), "{t:?}");
            assert_eq!(parse_i64(t.as_bytes()), t.parse().ok(), "{t:?}");
        }
    }
}
