//! Text as edmd reads and writes it: the byte-order mark skipped, numbers in messages.

/// The UTF-8 byte-order mark, which some Windows editors and CAM posts write at the start of
/// a file. It is not text: programs, configurations and gap scripts skip it.
pub const BOM: &str = "\u{feff}";

/// `text` without a leading byte-order mark.
pub fn without_bom(text: &str) -> &str {
    text.strip_prefix(BOM).unwrap_or(text)
}

/// A number in a message, as a person writes it: at most six decimals and no trailing
/// zeros (`0.1`, not `0.10000000000000178`), in scientific notation beyond 10^9 or below
/// 10^-6 (`1e200`, not two hundred digits).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Num(pub f64);

impl std::fmt::Display for Num {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let v = self.0;
        if !v.is_finite() {
            return write!(f, "{v}");
        }
        let trim = |s: String| -> String {
            if s.contains('.') {
                s.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                s
            }
        };
        let a = v.abs();
        if a != 0.0 && !(1e-6..1e9).contains(&a) {
            let text = format!("{v:.5e}");
            let (mantissa, exponent) = text.split_once('e').unwrap_or((&text, "0"));
            return write!(f, "{}e{exponent}", trim(mantissa.to_string()));
        }
        let text = trim(format!("{v:.6}"));
        f.write_str(if text == "-0" { "0" } else { &text })
    }
}
