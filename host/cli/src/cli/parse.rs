//! Value parsers for structured command-line values: clap calls them while parsing, so a bad
//! value is a usage error (exit 2) that says what is wanted, before any work starts.

use meb_core::capture::raw::RawLayout;
use meb_device::settings::{DepthRequest, Spelling};
use meb_pipeline::demod::{LedCount, Linearize, ModulationDepths, Roi};
use meb_pipeline::tof::chequerboard::BoardSize;

/// Parses `--leds`: 1..=8 or `auto`.
pub fn leds(text: &str) -> Result<LedCount, String> {
    if text == "auto" {
        return Ok(LedCount::Auto);
    }
    match text.parse::<usize>() {
        Ok(n) if (1..=8).contains(&n) => Ok(LedCount::Fixed(n)),
        _ => Err("a number of LEDs from 1 to 8, or `auto`".into()),
    }
}

/// Parses `--depth` of a capture: `auto`, one depth or one per LED in (0, 1] as
/// `meb device set --depth` takes them, or `factory` (the factory default's off levels).
pub fn depth(text: &str) -> Result<ModulationDepths, String> {
    if text.trim() == "factory" {
        return Ok(ModulationDepths::Factory);
    }
    match DepthRequest::parse(text, &Spelling::CLI).map_err(|e| e.to_string())? {
        DepthRequest::Auto => Ok(ModulationDepths::LowRiskAuto),
        DepthRequest::Depths(depths) => Ok(ModulationDepths::Depths(
            depths.into_iter().map(f64::from).collect(),
        )),
    }
}

/// Parses `meb device set --depth`: `auto`, or one depth or one per LED in (0, 1].
pub fn device_depth(text: &str) -> Result<DepthRequest, String> {
    DepthRequest::parse(text, &Spelling::CLI).map_err(|e| e.to_string())
}

/// Parses `--linearize`: `none`, `srgb` or `gamma:G` with G > 0.
pub fn linearize(text: &str) -> Result<Linearize, String> {
    match text {
        "none" => Ok(Linearize::None),
        "srgb" => Ok(Linearize::Srgb),
        other => match other.strip_prefix("gamma:").map(str::parse::<f32>) {
            Some(Ok(g)) if g.is_finite() && g > 0.0 => Ok(Linearize::Gamma(g)),
            _ => Err("`none`, `srgb` or `gamma:G` with a positive G, e.g. gamma:2.2".into()),
        },
    }
}

/// Parses "WxH+X+Y" (the offset may be left out: "WxH").
pub fn roi(text: &str) -> Result<Roi, String> {
    let wanted = || "WxH+X+Y with whole numbers, e.g. 640x360+320+180".to_string();
    let (size, offset) = text.split_once('+').unwrap_or((text, "0+0"));
    let (w, h) = size.split_once('x').ok_or_else(wanted)?;
    let (x, y) = offset.split_once('+').ok_or_else(wanted)?;
    let number = |v: &str| v.trim().parse::<usize>().map_err(|_| wanted());
    let roi = Roi {
        width: number(w)?,
        height: number(h)?,
        x: number(x)?,
        y: number(y)?,
    };
    if roi.width == 0 || roi.height == 0 {
        return Err("the region needs a width and a height of at least one pixel".into());
    }
    Ok(roi)
}

/// Parses "WxHxBITS".
pub fn raw(text: &str) -> Result<RawLayout, String> {
    let wanted = || "WxHxBITS with whole numbers, e.g. 1280x720x8".to_string();
    let parts: Vec<&str> = text.split('x').collect();
    let [w, h, b] = parts.as_slice() else {
        return Err(wanted());
    };
    Ok(RawLayout {
        width: w.parse().map_err(|_| wanted())?,
        height: h.parse().map_err(|_| wanted())?,
        bit_depth: b.parse().map_err(|_| wanted())?,
    })
}

/// A finite number above zero.
pub fn positive(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err("a finite number above 0".into()),
    }
}

/// A finite number of at least zero.
pub fn non_negative(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err("a finite number of at least 0".into()),
    }
}

/// A fraction in (0, 1].
pub fn fraction(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v > 0.0 && v <= 1.0 => Ok(v),
        _ => Err("a fraction above 0 and at most 1".into()),
    }
}

/// Parses "WxH" in pixels, both at least 1 (e.g. 384x216).
pub fn size(text: &str) -> Result<(usize, usize), String> {
    text.split_once(['x', 'X'])
        .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)))
        .filter(|&(w, h): &(usize, usize)| w > 0 && h > 0)
        .ok_or_else(|| "WxH in pixels, e.g. 384x216".into())
}

/// Parses "A..B" with A < B, finite (e.g. 650..760).
pub fn interval(text: &str) -> Result<(f64, f64), String> {
    text.split_once("..")
        .and_then(|(a, b)| Some((a.trim().parse().ok()?, b.trim().parse().ok()?)))
        .filter(|&(a, b): &(f64, f64)| a.is_finite() && b.is_finite() && a < b)
        .ok_or_else(|| "A..B with A < B, e.g. 650..760".into())
}

/// Parses a chequerboard's inner corners "COLSxROWS" (e.g. 9x6).
pub fn board(text: &str) -> Result<BoardSize, String> {
    BoardSize::parse(text).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn structured_values_parse_or_say_what_is_wanted() {
        assert_eq!(leds("auto"), Ok(LedCount::Auto));
        assert_eq!(leds("4"), Ok(LedCount::Fixed(4)));
        assert!(leds("9").is_err() && leds("0").is_err() && leds("four").is_err());
        assert_eq!(linearize("gamma:2.2"), Ok(Linearize::Gamma(2.2)));
        assert!(linearize("gamma:-1").is_err() && linearize("log").is_err());
        let r = roi("64x48+10+20").unwrap();
        assert_eq!((r.width, r.height, r.x, r.y), (64, 48, 10, 20));
        assert_eq!(roi("64x48").unwrap().x, 0);
        assert!(roi("0x48+1+1").is_err() && roi("64-48").is_err());
        let l = raw("1280x720x8").unwrap();
        assert_eq!((l.width, l.height, l.bit_depth), (1280, 720, 8));
        assert!(raw("1280x720").unwrap_err().contains("WxHxBITS"));
        assert_eq!(size("384x216"), Ok((384, 216)));
        assert!(size("384x0").is_err() && size("384").is_err());
        assert_eq!(interval("650..760"), Ok((650.0, 760.0)));
        assert!(interval("760..650").is_err() && interval("650-760").is_err());
        assert!(fraction("0").is_err() && fraction("1").is_ok() && fraction("1.5").is_err());
        assert!(positive("0").is_err() && positive("inf").is_err() && positive("2").is_ok());
        assert!(non_negative("0").is_ok() && non_negative("-1").is_err());
        assert!(board("9x6").is_ok() && board("9").is_err());
    }
}
