//! What an operator asks a technology for: `material=steel,height=32,wire=0.25` on the
//! command line, or `(TECH material=steel height=32 wire=0.25)` in a program's header.

use std::io::Read as _;
use std::path::Path;

use super::{Place, TechError};

/// A technology request, by kind.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Request {
    /// A wire cut: the work material, the part height (mm), the wire diameter (mm) and,
    /// where tables for two wire types fit, the type.
    Wire {
        material: String,
        height_mm: f64,
        wire_mm: f64,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        wire_type: Option<String>,
    },
    /// A sinking job: the electrode's material, the work material, the electrode's area
    /// (cm², the frontal area that sparks).
    Sinker {
        electrode: String,
        material: String,
        area_cm2: f64,
    },
}

/// The keys a request takes, for messages.
const KEYS: &str = "material, height (mm), wire (mm), type (the wire's); or electrode, \
                    material, area (cm²)";

impl Request {
    /// Reads `text` (`key=value` pairs, separated by commas or spaces); `source` and `line`
    /// locate it in messages, `col` is where `text` starts on that line.
    pub fn parse(text: &str, source: &str, line: usize, col: usize) -> Result<Request, TechError> {
        let at = |offset: usize, message: String| TechError::Request {
            at: Place {
                file: source.to_string(),
                line,
                col: col + text[..offset].chars().count(),
            },
            message,
        };
        let mut material = None;
        let (mut height, mut wire, mut wire_type) = (None, None, None);
        let (mut electrode, mut area) = (None, None);
        let mut offset = 0;
        for part in text.split([',', ' ', '\t']) {
            let start = offset;
            offset += part.len() + 1;
            if part.is_empty() {
                continue;
            }
            let Some((key, value)) = part.split_once('=') else {
                return Err(at(start, format!("{part:?} is not key=value ({KEYS})")));
            };
            let value_at = start + key.len() + 1;
            if value.is_empty() {
                return Err(at(value_at, format!("{key}= has no value")));
            }
            let number = |what: &str| {
                value
                    .parse::<f64>()
                    .ok()
                    .filter(|v| v.is_finite() && *v > 0.0)
                    .ok_or_else(|| at(value_at, format!("{key}={value}: {what}, above 0")))
            };
            let twice = || at(start, format!("{key} is given twice"));
            match key.to_ascii_lowercase().as_str() {
                "material" => put(&mut material, value.to_string()).ok_or_else(twice)?,
                "height" => put(&mut height, number("the part height in mm")?).ok_or_else(twice)?,
                "wire" => put(&mut wire, number("the wire diameter in mm")?).ok_or_else(twice)?,
                "type" => put(&mut wire_type, value.to_string()).ok_or_else(twice)?,
                "electrode" => put(&mut electrode, value.to_string()).ok_or_else(twice)?,
                "area" => put(&mut area, number("the electrode area in cm²")?).ok_or_else(twice)?,
                _ => {
                    return Err(at(
                        start,
                        format!("{key:?} is not a technology key ({KEYS})"),
                    ));
                }
            }
        }
        let missing = |what: &str| at(0, format!("{text:?} does not say {what} ({KEYS})"));
        let material = material.ok_or_else(|| missing("the material"))?;
        match (electrode, area, height, wire) {
            (None, None, height, wire) => Ok(Request::Wire {
                material,
                height_mm: height.ok_or_else(|| missing("the height"))?,
                wire_mm: wire.ok_or_else(|| missing("the wire diameter (wire=)"))?,
                wire_type,
            }),
            (electrode, area, None, None) if wire_type.is_none() => Ok(Request::Sinker {
                electrode: electrode.ok_or_else(|| missing("the electrode"))?,
                material,
                area_cm2: area.ok_or_else(|| missing("the electrode area (area=)"))?,
            }),
            _ => Err(at(
                0,
                "a request is for a wire cut (material, height, wire) or a sinking job \
                 (electrode, material, area), not both"
                    .into(),
            )),
        }
    }

    /// The request as it is written back: `material=steel height=32 wire=0.25`.
    pub fn text(&self) -> String {
        match self {
            Request::Wire {
                material,
                height_mm,
                wire_mm,
                wire_type,
            } => {
                let mut text = format!("material={material} height={height_mm} wire={wire_mm}");
                if let Some(t) = wire_type {
                    text += &format!(" type={t}");
                }
                text
            }
            Request::Sinker {
                electrode,
                material,
                area_cm2,
            } => format!("electrode={electrode} material={material} area={area_cm2}"),
        }
    }
}

/// Fills an empty slot; `None` when it was full (a key given twice).
fn put<T>(slot: &mut Option<T>, value: T) -> Option<()> {
    match slot {
        Some(_) => None,
        None => {
            *slot = Some(value);
            Some(())
        }
    }
}

/// The longest header read for a `(TECH …)` comment (bytes): a program whose comments run on
/// past it before the first block is refused, not read as having no technology.
pub const HEADER_BYTES: u64 = 1024 * 1024;

/// What the header of a text says.
enum Header {
    Request(Request),
    /// The first block came: no request.
    Ended,
    /// The text ended inside the header.
    Open {
        lines: usize,
    },
}

/// The `(TECH …)` comment in the header of `text` (the lines before its first block:
/// blank lines, `%`, comments), with its place; `source` names it in messages.
pub fn header_of(text: &str, source: &str) -> Result<Option<Request>, TechError> {
    Ok(match scan(text, source)? {
        Header::Request(r) => Some(r),
        Header::Ended | Header::Open { .. } => None,
    })
}

fn scan(text: &str, source: &str) -> Result<Header, TechError> {
    let mut lines = 0;
    for (i, line) in text.lines().enumerate() {
        lines = i + 1;
        let trimmed = line.trim_start();
        if trimmed.is_empty() || trimmed.starts_with('%') || trimmed.starts_with(';') {
            continue;
        }
        // Only comments on the line: each may be the request.
        let mut rest = trimmed;
        while let Some(open) = rest.strip_prefix('(') {
            let Some(close) = open.find(')') else {
                // An unclosed comment: the reader refuses it; no request here.
                return Ok(Header::Ended);
            };
            let comment = &open[..close];
            let word = comment
                .split([' ', '\t', ',', ':'])
                .next()
                .unwrap_or_default();
            if word.eq_ignore_ascii_case("TECH") {
                let after = &comment[word.len()..];
                let body = after.trim_start_matches([':', ' ', '\t', ',']);
                let col = line.len() - rest.len() + 2 + word.len() + (after.len() - body.len());
                return Request::parse(body, source, i + 1, col).map(Header::Request);
            }
            rest = open[close + 1..].trim_start();
        }
        if !rest.is_empty() {
            // The first block: the header is over.
            return Ok(Header::Ended);
        }
    }
    Ok(Header::Open { lines })
}

/// The `(TECH …)` comment in the header of the program at `path`, wherever it stands in the
/// header; a header that runs past [`HEADER_BYTES`] is refused at the line where it passes.
pub fn header(path: &Path, source: &str) -> Result<Option<Request>, TechError> {
    let mut text = Vec::new();
    crate::sys::open_regular(path)
        .and_then(|f| f.take(HEADER_BYTES + 1).read_to_end(&mut text))
        .map_err(|source| TechError::Program {
            path: path.to_path_buf(),
            source,
        })?;
    let past = text.len() as u64 > HEADER_BYTES;
    if past {
        // Only whole lines: a line cut at the bound is no line of the header.
        let whole = text[..HEADER_BYTES as usize]
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |nl| nl + 1);
        text.truncate(whole);
    }
    match scan(&String::from_utf8_lossy(&text), source)? {
        Header::Request(r) => Ok(Some(r)),
        Header::Ended => Ok(None),
        Header::Open { .. } if !past => Ok(None),
        Header::Open { lines } => Err(TechError::Request {
            at: Place {
                file: source.to_string(),
                line: lines.max(1),
                col: 1,
            },
            message: format!(
                "the program's header (its comments before the first block) runs past {} KiB: \
                 a (TECH …) comment beyond it would not be read; put the request first",
                HEADER_BYTES / 1024
            ),
        }),
    }
}
