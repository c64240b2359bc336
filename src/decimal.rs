//! Numbers as text, fast: an `f64` as the shortest decimal that reads back as the same double,
//! laid out exactly as std's `{}` and `{:e}` lay it out, an `f64` to a few fixed places as
//! `{:.2}` rounds it (`core::fmt` only near a tie), and integers, appended to a byte buffer
//! without allocating.
//!
//! Why not `format!`: `edmd plan` writes a trace row per segment, a dozen numbers a row, and
//! `core::fmt`'s shortest-digits path (Grisu with a Dragon fallback, behind the formatter's
//! padding machinery) cost about 13,000 instructions a row, more than segmenting and planning
//! the segment. A Ryū-family search (the `zmij` crate, Schubfach's method; "Ryū" below) finds
//! the same shortest round-trip digits in under two hundred; it lays them out its own way
//! (`1e-7`, `1.0`), so where that layout is not std's this module takes its digits and
//! exponent and writes them in std's layout. A test holds the two equal on millions of
//! doubles, so a trace written here is byte-for-byte the one `format!` wrote.
//!
//! Must never: import another edmd module outside its tests, allocate beyond growing the
//! caller's buffer, or print a number that reads back as a different double.

/// A decimal `0.d₁d₂…dₙ × 10^point` with `d₁ ≠ 0` and `dₙ ≠ 0` (no digits for zero).
struct Digits {
    negative: bool,
    digits: [u8; 20],
    len: usize,
    point: i32,
}

impl Digits {
    /// The shortest round-trip digits of a finite `x`.
    fn of(x: f64) -> Digits {
        let mut buffer = zmij::Buffer::new();
        let text = buffer.format_finite(x).as_bytes();
        let (negative, text) = match text.split_first() {
            Some((b'-', rest)) => (true, rest),
            _ => (false, text),
        };
        let (mantissa, exponent) = match text.iter().position(|&b| b == b'e') {
            Some(e) => (&text[..e], parse_exponent(&text[e + 1..])),
            None => (text, 0),
        };
        let mut d = Digits {
            negative,
            digits: [0; 20],
            len: 0,
            point: 0,
        };
        // Digits before the mantissa's point count towards `point`; leading zeros do not
        // count as digits, and a zero before the point is not a digit either.
        let mut before_point = true;
        for &b in mantissa {
            if b == b'.' {
                before_point = false;
                continue;
            }
            if d.len == 0 && b == b'0' {
                if !before_point {
                    d.point -= 1;
                }
                continue;
            }
            d.digits[d.len] = b;
            d.len += 1;
            if before_point {
                d.point += 1;
            }
        }
        while d.len > 0 && d.digits[d.len - 1] == b'0' {
            d.len -= 1;
        }
        if d.len == 0 {
            d.point = 0;
        }
        d.point += exponent;
        if d.len > 0 && d.is_tie_below(x) {
            d.round_up();
        }
        d
    }

    /// Whether `|x|` lies exactly halfway between these digits and the next decimal up of the
    /// same length. Ryū breaks such a tie to an even last digit, std upwards; both are the
    /// same distance from `x`, so both read back as `x`, and std's is the one to print.
    ///
    /// With `|x| = m · 2^e` (`m` odd) and the halfway point `(2D + 1) · 5^(f+1) · 2^f`
    /// (`D` the digits as an integer, `f` one below the last digit's power of ten), the two
    /// are equal exactly when the powers of two agree and the odd parts do: integers only.
    fn is_tie_below(&self, x: f64) -> bool {
        let (m, e) = odd_mantissa(x);
        let f = self.point - self.len as i32 - 1;
        if e != f {
            return false;
        }
        let d = self
            .digits()
            .iter()
            .fold(0u128, |v, &b| v * 10 + u128::from(b - b'0'));
        let odd = 2 * d + 1;
        let five = |k: i32| 5u128.checked_pow(k.unsigned_abs());
        if f + 1 >= 0 {
            five(f + 1).and_then(|p| odd.checked_mul(p)) == Some(u128::from(m))
        } else {
            five(f + 1).and_then(|p| u128::from(m).checked_mul(p)) == Some(odd)
        }
    }

    /// The next decimal up with this many digits (or one digit fewer: `99` becomes `1` with
    /// the point moved), trailing zeros dropped.
    fn round_up(&mut self) {
        let mut i = self.len;
        loop {
            if i == 0 {
                self.digits[0] = b'1';
                self.len = 1;
                self.point += 1;
                return;
            }
            i -= 1;
            if self.digits[i] == b'9' {
                self.digits[i] = b'0';
            } else {
                self.digits[i] += 1;
                break;
            }
        }
        while self.digits[self.len - 1] == b'0' {
            self.len -= 1;
        }
    }

    fn digits(&self) -> &[u8] {
        &self.digits[..self.len]
    }
}

fn parse_exponent(text: &[u8]) -> i32 {
    let (negative, digits) = match text.split_first() {
        Some((b'-', rest)) => (true, rest),
        Some((b'+', rest)) => (false, rest),
        _ => (false, text),
    };
    let value = digits
        .iter()
        .fold(0i32, |v, &b| v * 10 + i32::from(b - b'0'));
    if negative { -value } else { value }
}

/// Non-finite values as std prints them (`NaN`, `inf`, `-inf`); `false` for a finite `x`.
fn push_non_finite(out: &mut Vec<u8>, x: f64) -> bool {
    if x.is_nan() {
        out.extend_from_slice(b"NaN");
    } else if x.is_infinite() {
        out.extend_from_slice(if x < 0.0 { b"-inf" } else { b"inf" });
    } else {
        return false;
    }
    true
}

/// The exponent field of doubles from 2^53 up: below it, a whole double is its own shortest
/// decimal.
const WHOLE_FIELD_BELOW: u32 = EXPONENT_BIAS + 53;

/// The exponent field of 1.0.
const EXPONENT_BIAS: u32 = 1023;

/// The biased exponent of a double, from its bits.
#[inline(always)]
fn exponent_field(bits: u64) -> u32 {
    ((bits >> 52) & 0x7ff) as u32
}

/// `|x|` when the double with these bits (and exponent `field`, below [`WHOLE_FIELD_BELOW`])
/// is a whole number; `None` when it has a fraction. From the bits: the conversion to an
/// integer and back it replaces cost twice as many instructions, six numbers a row.
#[inline(always)]
fn whole_magnitude(bits: u64, field: u32) -> Option<u64> {
    if field < EXPONENT_BIAS {
        // Below 1 only zero is whole (a subnormal has a fraction).
        return (bits << 1 == 0).then_some(0);
    }
    // `integer_bits` of the 52 stored fraction bits lie before the binary point; any set
    // bit after them is a fraction.
    let integer_bits = field - EXPONENT_BIAS;
    if (bits << 12) << integer_bits != 0 {
        return None;
    }
    Some(((bits & FRACTION_BITS) | 1 << 52) >> (52 - integer_bits))
}

fn push_zeros(out: &mut Vec<u8>, n: usize) {
    out.resize(out.len() + n, b'0');
}

/// Appends `x` as `format!("{x}")` prints it: the shortest round-trip digits, never an
/// exponent (`0.0000001`, `1000000000000000000000`), no point for a whole number (`1`, `-0`).
///
/// Inlined where it is called, with the two cases a trace row is made of up front: a whole
/// number below 2^53 and a fraction whose shortest digits Ryū lays out as std does. Everything
/// else (non-finite, tiny, a possible tie) goes to [`push_f64_general`]. As a call of its own
/// this front cost about fifty instructions a number before the conversion started, six
/// numbers a row.
#[inline(always)]
pub fn push_f64(out: &mut Vec<u8>, x: f64) {
    let bits = x.to_bits();
    let field = exponent_field(bits);
    // `NaN` and the infinities (the largest field) fail the first test.
    if field < WHOLE_FIELD_BELOW {
        if let Some(whole) = whole_magnitude(bits, field) {
            // A whole number (a feed of `600`, a coordinate of `0`) is its own shortest
            // decimal: the integer's digits, a sign for `-0` too.
            if x.is_sign_negative() {
                out.push(b'-');
            }
            push_u64(out, whole);
            return;
        }
        // A fraction is below 2^52, so Ryū writes it without an exponent from `1e-5` up,
        // and never with a bare `.0`: its layout is std's.
        if field >= PLAIN_FIELD_FROM && !fraction_may_tie(bits, field) {
            out.extend_from_slice(zmij::Buffer::new().format_finite(x).as_bytes());
            return;
        }
    }
    push_f64_general(out, x);
}

/// [`push_f64`] for what its fast cases leave (a whole number from 2^53, a fraction below
/// `1e-5` or one that may be a tie, non-finite values): through the digits, with std's tie
/// rule applied.
#[cold]
#[inline(never)]
fn push_f64_general(out: &mut Vec<u8>, x: f64) {
    if push_non_finite(out, x) {
        return;
    }
    let d = Digits::of(x);
    if d.negative {
        out.push(b'-');
    }
    let digits = d.digits();
    if digits.is_empty() {
        out.push(b'0');
    } else if d.point <= 0 {
        out.extend_from_slice(b"0.");
        push_zeros(out, d.point.unsigned_abs() as usize);
        out.extend_from_slice(digits);
    } else if (d.point as usize) < digits.len() {
        let (whole, fraction) = digits.split_at(d.point as usize);
        out.extend_from_slice(whole);
        out.push(b'.');
        out.extend_from_slice(fraction);
    } else {
        out.extend_from_slice(digits);
        push_zeros(out, d.point as usize - digits.len());
    }
}

/// The exponent field from which Ryū writes a fraction without an exponent: that of 2^-16,
/// the first power of two above `1e-5`.
///
/// Ryū writes shortest digits from `1e-5` up to but not including `1e16` without one. Both
/// ends are doubles' own shortest digits, and the shortest digits of a double lie between its
/// neighbours, so the digits of `x` are in that range exactly when `x` is. From 2^-16 up `x`
/// is, and the exponent field, already at hand, says so in one comparison (a float
/// comparison of `|x|` took three more instructions, six numbers a row); the few doubles
/// between `1e-5` and 2^-16 go the general way. (The upper end needs no test: a double with
/// a fraction is below 2^52.) `edge_values_print_as_std_prints_them` walks the neighbours of
/// `1e-5`, 2^-16 and `1e16`.
const PLAIN_FIELD_FROM: u32 = EXPONENT_BIAS - 16;

/// Whether the shortest digits of the fraction `m · 2^e` (`m` odd, `e < 0`) could be a tie
/// between two candidates (see [`Digits::is_tie_below`]): only when its exact decimal
/// expansion, the digits of `m · 5^-e`, has at most 18 significant digits, one more than
/// the shortest can have.
fn may_tie(m: u64, e: i32) -> bool {
    let k = e.unsigned_abs() as usize;
    k < POW5.len() && u128::from(m) * u128::from(POW5[k]) < 1_000_000_000_000_000_000
}

/// [`may_tie`] for a normal double with a fraction (what [`push_f64`]'s fast path sees), from
/// its bits and exponent `field`: without the zero and subnormal cases of [`odd_mantissa`].
///
/// With `|x| = m · 2^-k` (`m` odd), `k` is `EXPONENT_BIAS + 52 − field` less the mantissa's
/// trailing zero bits, and only `k` below [`POW5`]'s length can tie. A trace's fractions have
/// `k` far above it, which the sum of the field and those zeros tells in a few instructions;
/// the odd mantissa itself is taken only below it.
#[inline(always)]
fn fraction_may_tie(bits: u64, field: u32) -> bool {
    // The implicit bit bounds the count at 52, whatever lies above it.
    let zeros = (bits | 1 << 52).trailing_zeros();
    if field + zeros + POW5.len() as u32 <= EXPONENT_BIAS + 52 {
        return false;
    }
    let (m, e) = normal_odd_mantissa(bits);
    may_tie(m, e)
}

/// `5^k` for the `k` where `m · 5^k` can stay under 10^18.
const POW5: [u64; 27] = {
    let mut table = [1u64; 27];
    let mut k = 1;
    while k < table.len() {
        table[k] = table[k - 1] * 5;
        k += 1;
    }
    table
};

/// `|x| = m · 2^e` with `m` odd (or zero).
fn odd_mantissa(x: f64) -> (u64, i32) {
    let bits = x.to_bits();
    if exponent_field(bits) != 0 {
        return normal_odd_mantissa(bits);
    }
    match bits & FRACTION_BITS {
        0 => (0, 0),
        // A subnormal's last bit is worth 2^(1 − bias − 52).
        fraction => without_twos(fraction, 1 - EXPONENT_BIAS as i32 - 52),
    }
}

/// [`odd_mantissa`] of a normal double (exponent field not zero), from its bits.
#[inline]
fn normal_odd_mantissa(bits: u64) -> (u64, i32) {
    let field = exponent_field(bits) as i32;
    // The mantissa's last bit is worth 2^(field − bias − 52).
    without_twos(
        (bits & FRACTION_BITS) | (1 << 52),
        field - EXPONENT_BIAS as i32 - 52,
    )
}

/// The stored fraction of a double.
const FRACTION_BITS: u64 = (1 << 52) - 1;

/// `m · 2^e` (`m` not zero) with the factors of two moved from `m` to the exponent.
#[inline]
fn without_twos(m: u64, e: i32) -> (u64, i32) {
    let zeros = m.trailing_zeros();
    (m >> zeros, e + zeros as i32)
}

/// Appends `x` as `format!("{x:e}")` prints it: the shortest round-trip digits as
/// `d.ddd` times a power of ten (`1.5e-7`, `1e0`, `0e0`).
pub fn push_f64_exp(out: &mut Vec<u8>, x: f64) {
    if push_non_finite(out, x) {
        return;
    }
    let d = Digits::of(x);
    if d.negative {
        out.push(b'-');
    }
    let digits = d.digits();
    let exponent = match digits.split_first() {
        None => {
            out.push(b'0');
            0
        }
        Some((first, rest)) => {
            out.push(*first);
            if !rest.is_empty() {
                out.push(b'.');
                out.extend_from_slice(rest);
            }
            d.point - 1
        }
    };
    out.push(b'e');
    push_i64(out, i64::from(exponent));
}

/// Appends `x` as `format!("{x:.places$}")` prints it, for `places` up to 3: a chart's pixel
/// coordinate (`123.46`, `-0.00`).
///
/// `core::fmt` rounds the exact binary value to `places` decimals, ties to even, through Grisu
/// with a Dragon fallback: about a thousand instructions a number, and a chart of a long plan
/// has hundreds of thousands. Here the value is scaled by `10^places` in floating point; below
/// 2^30 that product is within 1.2e-7 of the exact one, so wherever its fraction is more than
/// 1e-6 from one half, rounding it rounds the exact value the same way. Near a tie, and for
/// large or non-finite values, `core::fmt` itself writes the number.
///
/// Inlined, so that a caller's constant `places` folds the scale, the divisions and the digit
/// loop (a chart's coordinates all have two: a quarter of a million numbers in a long plan);
/// what goes to `core::fmt` is a call.
#[inline(always)]
pub fn push_fixed(out: &mut Vec<u8>, x: f64, places: usize) {
    const SCALES: [f64; 4] = [1.0, 10.0, 100.0, 1000.0];
    const TIE_MARGIN: f64 = 1e-6;
    let scaled = x.abs() * SCALES[places];
    // `NaN < limit` is false: NaN goes to `core::fmt` too.
    if scaled < 1_073_741_824.0 {
        let whole = scaled as u64;
        let fraction = scaled - whole as f64;
        if (fraction - 0.5).abs() > TIE_MARGIN {
            let rounded = whole + u64::from(fraction > 0.5);
            // std keeps the sign of what rounds to zero: `-0.00`.
            if x.is_sign_negative() {
                out.push(b'-');
            }
            let unit = 10u64.pow(places as u32);
            push_u64(out, rounded / unit);
            if places > 0 {
                out.push(b'.');
                let mut digits = [b'0'; 3];
                let mut rest = rounded % unit;
                for slot in digits[..places].iter_mut().rev() {
                    *slot = b'0' + (rest % 10) as u8;
                    rest /= 10;
                }
                out.extend_from_slice(&digits[..places]);
            }
            return;
        }
    }
    push_fixed_general(out, x, places);
}

/// [`push_fixed`] near a tie, and for large or non-finite values: through `core::fmt`.
#[cold]
#[inline(never)]
fn push_fixed_general(out: &mut Vec<u8>, x: f64, places: usize) {
    use std::io::Write as _;
    // Writing to a Vec cannot fail.
    let _ = write!(out, "{x:.places$}");
}

/// Appends an integer in decimal, as `{}` prints it.
fn push_i64(out: &mut Vec<u8>, n: i64) {
    out.extend_from_slice(itoa::Buffer::new().format(n).as_bytes());
}

/// Appends an unsigned integer in decimal, as `{}` prints it. Up to three digits (a trace
/// row's evaluations, a coordinate of `0`, a feed of `600`) are written in place: through
/// `itoa` and a copy a number cost sixty-odd instructions, a row has three, and a plan has a
/// million rows.
#[inline(always)]
pub fn push_u64(out: &mut Vec<u8>, n: u64) {
    let digit = |d: u64| b'0' + d as u8;
    if n < 10 {
        out.push(digit(n));
    } else if n < 100 {
        out.extend_from_slice(&[digit(n / 10), digit(n % 10)]);
    } else if n < 1000 {
        out.extend_from_slice(&[digit(n / 100), digit(n / 10 % 10), digit(n % 10)]);
    } else {
        out.extend_from_slice(itoa::Buffer::new().format(n).as_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn display(x: f64) -> String {
        let mut out = Vec::new();
        push_f64(&mut out, x);
        String::from_utf8(out).unwrap()
    }

    fn exp(x: f64) -> String {
        let mut out = Vec::new();
        push_f64_exp(&mut out, x);
        String::from_utf8(out).unwrap()
    }

    fn same_as_std(x: f64) {
        assert_eq!(
            display(x),
            format!("{x}"),
            "{{}} of {:e} ({:#x})",
            x,
            x.to_bits()
        );
        assert_eq!(
            exp(x),
            format!("{x:e}"),
            "{{:e}} of {:e} ({:#x})",
            x,
            x.to_bits()
        );
    }

    #[test]
    fn edge_values_print_as_std_prints_them() {
        let edges = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.1,
            0.3,
            1.5,
            10.0,
            100.0,
            123.456,
            1e-7,
            1.5e-7,
            1e15,
            1e16,
            1.2345e16,
            1e21,
            1e22,
            1e300,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            f64::EPSILON,
            5e-324,
            -5e-324,
            9007199254740993.0,
            9007199254740992.0,
            -9007199254740992.0,
            9007199254740991.0,
            -9007199254740991.0,
            600.0,
            -600.0,
            i64::MAX as f64,
            i64::MIN as f64,
            0.000_001,
            2.703574470692675,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ];
        for x in edges {
            same_as_std(x);
        }
        // Whole numbers and the fractions next to them, at every power of two up to 2^54
        // (where the point falls before, among and after the mantissa's bits), both signs.
        for k in 0..=54 {
            let power = 2f64.powi(k);
            let mut below = power;
            let mut above = power;
            for _ in 0..4 {
                for x in [
                    below,
                    above,
                    power + 0.5,
                    power - 0.5,
                    power + 0.25,
                    power + 3.0,
                ] {
                    same_as_std(x);
                    same_as_std(-x);
                }
                below = below.next_down();
                above = above.next_up();
            }
        }
        // Either side of where Ryū's layout changes to an exponent and of where the fast path
        // starts, both signs (written out, not the constants, so a wrong constant fails here).
        for end in [1e-5, 2f64.powi(-16), 1e16] {
            let mut below = end;
            let mut above = end;
            for _ in 0..1000 {
                for x in [below, above] {
                    same_as_std(x);
                    same_as_std(-x);
                }
                below = below.next_down();
                above = above.next_up();
            }
        }
    }

    #[test]
    fn the_tie_filter_answers_as_the_full_test() {
        // Fractions of every exponent the fast path sees, with few and many trailing zero
        // bits (the filter's count), against `may_tie` on the odd mantissa. In that range
        // ties have `k` up to 22 (from 2^-16 up, a larger `k` leaves the odd mantissa too
        // many bits), which these draws reach: a filter that let `k` of 22 pass as no tie
        // fails here.
        let mut rng = crate::rng::SplitMix64::new(0x71e);
        let mut ties = 0;
        for _ in 0..count() {
            let field = PLAIN_FIELD_FROM + (rng.next_u64() % 60) as u32;
            let fraction = (rng.next_u64() << (rng.next_u64() % 53)) & FRACTION_BITS;
            let bits = u64::from(field) << 52 | fraction;
            if whole_magnitude(bits, field).is_some() {
                continue;
            }
            let (m, e) = normal_odd_mantissa(bits);
            assert_eq!(fraction_may_tie(bits, field), may_tie(m, e), "{bits:#x}");
            ties += usize::from(may_tie(m, e));
        }
        assert!(ties > count() / 200, "only {ties} possible ties drawn");
    }

    /// Doubles per family (`EDMD_DECIMAL_TESTS` raises it for a long run).
    fn count() -> usize {
        std::env::var("EDMD_DECIMAL_TESTS")
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(200_000)
    }

    #[test]
    fn random_doubles_print_as_std_prints_them() {
        // Random bit patterns cover every exponent; numbers of the size a trace holds
        // (coordinates, times, feeds, micron errors) cover the layouts it uses.
        let mut rng = crate::rng::SplitMix64::new(0x5eed);
        let n = count();
        for _ in 0..n {
            same_as_std(f64::from_bits(rng.next_u64()));
        }
        for _ in 0..n {
            let magnitude = (rng.next_u64() % 40) as i32 - 20;
            let x = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * 10f64.powi(magnitude);
            same_as_std(x);
            same_as_std(-x);
        }
        // Whole numbers, small and near 2^53 (the integer path's edge).
        for _ in 0..n {
            let x = ((rng.next_u64() >> 11) >> (rng.next_u64() % 54)) as f64;
            same_as_std(x);
            same_as_std(-x);
        }
        // Short dyadic numbers, whose exact decimals are short: where ties between two
        // shortest candidates live (Ryū rounds them to even, std up).
        for _ in 0..n {
            let m = (rng.next_u64() >> 40) as f64;
            let x = m * 2f64.powi((rng.next_u64() % 140) as i32 - 70);
            same_as_std(x);
        }
    }

    #[test]
    fn fixed_places_print_as_std_prints_them() {
        let fixed = |x: f64, places: usize| {
            let mut out = Vec::new();
            push_fixed(&mut out, x, places);
            String::from_utf8(out).unwrap()
        };
        let mut rng = crate::rng::SplitMix64::new(0xf1_7ed);
        let n = count();
        let check = |x: f64| {
            for places in 0..=3 {
                assert_eq!(
                    fixed(x, places),
                    format!("{x:.places$}"),
                    "{{:.{places}}} of {x:e} ({:#x})",
                    x.to_bits()
                );
            }
        };
        // Ties and near-ties (k/16 are exact halves at every place count), zeros, the edges of
        // the fast path, the non-finite values.
        for x in [
            0.0,
            -0.0,
            0.125,
            0.375,
            2.5,
            -2.5,
            -0.001,
            0.005,
            1.005,
            0.135,
            1_073_741_823.5,
            1_073_741_824.0,
            1e300,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            check(x);
        }
        for _ in 0..n {
            // Pixel coordinates and beyond, and short dyadic numbers (the ties).
            let magnitude = (rng.next_u64() % 14) as i32 - 4;
            let x = (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64 * 10f64.powi(magnitude);
            check(x);
            check(-x);
            let m = (rng.next_u64() >> 44) as f64;
            check(m / f64::from(1u32 << (rng.next_u64() % 12)));
        }
    }

    #[test]
    fn integers_print_as_std_prints_them() {
        for n in [0, 1, -1, 42, i64::MAX, i64::MIN] {
            let mut out = Vec::new();
            push_i64(&mut out, n);
            assert_eq!(out, n.to_string().into_bytes());
        }
        // Both sides of each short form, and the largest.
        for n in (0..=1001).chain([9999, 10_000, u64::MAX]) {
            let mut out = b"x".to_vec();
            push_u64(&mut out, n);
            assert_eq!(out, format!("x{n}").into_bytes());
        }
    }
}
