//! The attributes a user gives the series (`--dicom-meta FILE.json`): patient, study, series,
//! equipment and slide, by their DICOM keywords. Nothing here is ever invented: an attribute
//! not given is written empty where the IOD allows (type 2) or from what the run knows (the
//! slide's name, this program), and docs/dicom.md says which.
//!
//! The file is one JSON object of keyword to string (a number for `SeriesNumber`); an unknown
//! keyword, a value of the wrong form for its VR or too long for it is refused, naming it.

use std::collections::BTreeMap;

use crate::error::{Result, TilerError};

/// A value representation, as far as checking a user's value needs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Vr {
    /// Person name: up to 64 characters a component group.
    Pn,
    /// Long string, 64.
    Lo,
    /// Short string, 16.
    Sh,
    /// Code string: 16 of upper-case letters, digits, space, underscore.
    Cs,
    /// Date, YYYYMMDD.
    Da,
    /// Time, HHMMSS.FFFFFF (HH at least).
    Tm,
    /// Date-time, YYYYMMDDHHMMSS.FFFFFF (YYYY at least).
    Dt,
    /// UID: digits and dots, 64.
    Ui,
    /// Integer string, 12.
    Is,
}

impl Vr {
    /// The VR's two letters.
    pub fn code(self) -> &'static str {
        match self {
            Vr::Pn => "PN",
            Vr::Lo => "LO",
            Vr::Sh => "SH",
            Vr::Cs => "CS",
            Vr::Da => "DA",
            Vr::Tm => "TM",
            Vr::Dt => "DT",
            Vr::Ui => "UI",
            Vr::Is => "IS",
        }
    }
}

/// The keywords `--dicom-meta` takes, with their tags and VRs.
pub(super) const KEYWORDS: &[(&str, (u16, u16), Vr)] = &[
    ("PatientName", (0x0010, 0x0010), Vr::Pn),
    ("PatientID", (0x0010, 0x0020), Vr::Lo),
    ("PatientBirthDate", (0x0010, 0x0030), Vr::Da),
    ("PatientSex", (0x0010, 0x0040), Vr::Cs),
    ("StudyInstanceUID", (0x0020, 0x000D), Vr::Ui),
    ("StudyID", (0x0020, 0x0010), Vr::Sh),
    ("StudyDate", (0x0008, 0x0020), Vr::Da),
    ("StudyTime", (0x0008, 0x0030), Vr::Tm),
    ("AccessionNumber", (0x0008, 0x0050), Vr::Sh),
    ("ReferringPhysicianName", (0x0008, 0x0090), Vr::Pn),
    ("StudyDescription", (0x0008, 0x1030), Vr::Lo),
    ("SeriesDescription", (0x0008, 0x103E), Vr::Lo),
    ("SeriesNumber", (0x0020, 0x0011), Vr::Is),
    ("InstitutionName", (0x0008, 0x0080), Vr::Lo),
    ("Manufacturer", (0x0008, 0x0070), Vr::Lo),
    ("ManufacturerModelName", (0x0008, 0x1090), Vr::Lo),
    ("DeviceSerialNumber", (0x0018, 0x1000), Vr::Lo),
    ("SoftwareVersions", (0x0018, 0x1020), Vr::Lo),
    ("ContainerIdentifier", (0x0040, 0x0512), Vr::Lo),
    ("SpecimenIdentifier", (0x0040, 0x0551), Vr::Lo),
    ("AcquisitionDateTime", (0x0008, 0x002A), Vr::Dt),
];

/// The attributes given, by keyword, checked; none by default.
#[derive(Clone, Debug, Default, PartialEq, Eq, Hash)]
pub struct DicomMeta {
    values: BTreeMap<&'static str, String>,
}

impl DicomMeta {
    /// Parses `--dicom-meta`'s JSON; errors name the keyword and say what is wrong.
    pub fn from_json(text: &str) -> Result<DicomMeta> {
        let bad = |m: String| TilerError::Options(format!("--dicom-meta: {m}"));
        let value: serde_json::Value = serde_json::from_str(text).map_err(|e| bad(format!("not JSON ({e})")))?;
        let serde_json::Value::Object(map) = value else {
            return Err(bad("the file holds one JSON object of DICOM keywords, e.g. {\"PatientID\": \"P1\"}".into()));
        };
        let mut values = BTreeMap::new();
        for (key, value) in map {
            let Some(&(keyword, _, vr)) = KEYWORDS.iter().find(|(k, ..)| *k == key) else {
                let known: Vec<&str> = KEYWORDS.iter().map(|(k, ..)| *k).collect();
                return Err(bad(format!("unknown keyword {key:?}; the keywords taken are {}", known.join(", "))));
            };
            let text = match (value, vr) {
                (serde_json::Value::String(s), _) => s,
                (serde_json::Value::Number(n), Vr::Is) if n.is_i64() => n.to_string(),
                (other, _) => return Err(bad(format!("{keyword}: {other} is not a string"))),
            };
            check(&text, vr).map_err(|why| bad(format!("{keyword} {text:?}: {why} ({})", vr.code())))?;
            values.insert(keyword, text);
        }
        Ok(DicomMeta { values })
    }

    /// The value given for `keyword`, if any.
    pub fn get(&self, keyword: &str) -> Option<&str> {
        self.values.get(keyword).map(String::as_str)
    }

    /// Every value given, keyword first, in keyword order (for the UIDs' identity).
    pub fn iter(&self) -> impl Iterator<Item = (&'static str, &str)> {
        self.values.iter().map(|(k, v)| (*k, v.as_str()))
    }
}

/// Whether `text` is a value of `vr`: its length and its characters.
fn check(text: &str, vr: Vr) -> std::result::Result<(), String> {
    let most = match vr {
        Vr::Pn | Vr::Lo | Vr::Ui => 64,
        Vr::Sh | Vr::Cs => 16,
        Vr::Da => 8,
        Vr::Tm => 14,
        Vr::Dt => 26,
        Vr::Is => 12,
    };
    if text.chars().count() > most {
        return Err(format!("longer than {most} characters"));
    }
    if text.chars().any(|c| c.is_control() || c == '\\') {
        return Err("holds a control character or a backslash".into());
    }
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    let ok = match vr {
        Vr::Pn | Vr::Lo | Vr::Sh => true,
        Vr::Cs => text.bytes().all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b == b' ' || b == b'_'),
        Vr::Da => text.len() == 8 && digits(text),
        Vr::Tm | Vr::Dt => {
            let (whole, fraction) = text.split_once('.').unwrap_or((text, "0"));
            let least = if vr == Vr::Tm { 2 } else { 4 };
            let most = if vr == Vr::Tm { 6 } else { 14 };
            digits(whole)
                && (least..=most).contains(&whole.len())
                && whole.len().is_multiple_of(2)
                && (1..=6).contains(&fraction.len())
                && digits(fraction)
        }
        Vr::Ui => text.split('.').all(|p| !p.is_empty() && digits(p) && (p.len() == 1 || !p.starts_with('0'))),
        Vr::Is => text.trim().parse::<i32>().is_ok(),
    };
    if ok { Ok(()) } else { Err("not of this value representation's form".into()) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_keywords_given_are_kept_and_others_refused() {
        let meta = DicomMeta::from_json(
            r#"{"PatientName": "Doe^Jane", "PatientID": "P-1", "SeriesNumber": 4, "StudyDate": "20260102",
                "AcquisitionDateTime": "20260102101500", "StudyInstanceUID": "1.2.3.4"}"#,
        )
        .unwrap();
        assert_eq!(meta.get("PatientName"), Some("Doe^Jane"));
        assert_eq!(meta.get("SeriesNumber"), Some("4"));
        assert_eq!(meta.get("PatientSex"), None);
        for (json, want) in [
            (r#"{"PatientAge": "040Y"}"#, "unknown keyword \"PatientAge\""),
            (r#"["PatientID"]"#, "one JSON object"),
            ("{", "not JSON"),
            (r#"{"PatientBirthDate": "1970-01-01"}"#, "PatientBirthDate \"1970-01-01\""),
            (r#"{"PatientSex": "female"}"#, "PatientSex"),
            (r#"{"StudyID": "a study id longer than 16"}"#, "longer than 16"),
            (r#"{"PatientID": "a\\b"}"#, "backslash"),
            (r#"{"PatientID": 7}"#, "is not a string"),
            (r#"{"StudyInstanceUID": "1.2.x"}"#, "StudyInstanceUID"),
        ] {
            let e = DicomMeta::from_json(json).unwrap_err().to_string();
            assert!(e.contains(want), "{json}: {e}");
        }
    }
}
