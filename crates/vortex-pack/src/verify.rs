//! Checking a whole pack, byte by byte: what `vortex-tiler verify` runs.
//!
//! [`Pack::open`] has already checked the structure (signature, version, header checksum,
//! section bounds, level table and index checksum, metadata checksum, file length);
//! [`Pack::open_to_verify`] all but the index checksum, which `verify` checks itself, so that a
//! pack whose index is damaged gets a full report rather than one error. `verify`
//! checks everything else and accounts for every byte of the file: the header, level table,
//! index and metadata are covered by their checksums, each payload by its entry's CRC-32C, and
//! every other byte (between sections, between payloads, after the last one) is padding and
//! must be zero. So any single changed byte is reported. It does not stop at the first
//! problem: the [`Report`] lists all of them, each with its byte offset and tile where known.

use std::fmt::{self, Write as _};
use std::path::PathBuf;

use crate::format::{self, Description, ENTRY_LEN, Entry, FNV_OFFSET, HEADER_LEN, LEVEL_LEN, TileKind};
use crate::reader::{Pack, TileId};

#[cfg(feature = "decode")]
use crate::decode::PayloadDecoder;

/// What to check beyond structure and checksums. Without the `decode` feature there is
/// nothing to choose (decoding is not built, so it cannot be asked for).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VerifyOptions {
    /// Decode every distinct payload (raw, zstd, zstd-delta, PNG, JPEG, BC1, BC7) and check
    /// that it is exactly one tile, each held to the pack's
    /// [`Limits::max_decoded_bytes`](crate::Limits::max_decoded_bytes): a tile that would need
    /// more is a problem, not an allocation. Feature `decode`.
    #[cfg(feature = "decode")]
    pub decode: bool,
}

/// One thing wrong with a pack.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Problem {
    /// Byte offset in the file of the faulty bytes (the entry, the payload, the first non-zero
    /// padding byte), when there is one.
    pub offset: Option<u64>,
    /// The tile concerned, when there is one.
    pub tile: Option<TileId>,
    /// `header`, `levels`, `index`, `metadata`, `data` or `padding`.
    pub section: &'static str,
    /// What is wrong.
    pub message: String,
}

/// Everything `verify` found: counts, and every problem in file order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Report {
    /// The pack's file.
    pub path: PathBuf,
    /// Its length in bytes.
    pub file_bytes: u64,
    /// The header's content hash.
    pub content_hash: u64,
    /// Index entries (every tile address of every level).
    pub tiles: u64,
    /// Tiles of each kind, indexed by the kind's byte (`TileKind as usize`).
    pub kinds: [u64; TileKind::ALL.len()],
    /// Entries of no known kind.
    pub unknown_kinds: u64,
    /// Distinct payloads in the data section (inside it and not empty), and their bytes.
    pub stored_payloads: u64,
    /// Bytes of stored payloads (each shared payload once).
    pub payload_bytes: u64,
    /// Entries that point at a payload an earlier entry already points at (deduplication).
    pub shared_payloads: u64,
    /// Bytes that are neither header, table, index, metadata nor payload, all checked to be zero.
    pub padding_bytes: u64,
    /// Payloads decoded (with `VerifyOptions::decode`, feature `decode`).
    pub decoded_payloads: u64,
    /// Every problem found, in file order; none for a sound pack.
    pub problems: Vec<Problem>,
}

const KINDS: [TileKind; TileKind::ALL.len()] = TileKind::ALL;

impl Report {
    /// No problem found.
    pub fn is_ok(&self) -> bool {
        self.problems.is_empty()
    }

    /// Tiles of `kind`.
    pub fn count(&self, kind: TileKind) -> u64 {
        self.kinds[kind as usize]
    }

    /// The report as one JSON object: `path`, `ok`, the counts (`kinds` by name, `unknown`
    /// included), `content_hash` as a hex string, and `problems`, each with `section`,
    /// `offset` (or null), `tile` (`{lod, x, y}` or null) and `message`.
    pub fn to_json(&self) -> String {
        let mut s = String::new();
        s.push_str("{\"path\":");
        json_string(&mut s, &self.path.to_string_lossy());
        let _ = write!(
            s,
            ",\"ok\":{},\"file_bytes\":{},\"content_hash\":\"{:#018x}\",\"tiles\":{},\"kinds\":{{",
            self.is_ok(),
            self.file_bytes,
            self.content_hash,
            self.tiles
        );
        for kind in KINDS {
            let _ = write!(s, "\"{}\":{},", kind.name(), self.count(kind));
        }
        let _ = write!(
            s,
            "\"unknown\":{}}},\"stored_payloads\":{},\"payload_bytes\":{},\"shared_payloads\":{},\"padding_bytes\":{},\"decoded_payloads\":{},\"problems\":[",
            self.unknown_kinds,
            self.stored_payloads,
            self.payload_bytes,
            self.shared_payloads,
            self.padding_bytes,
            self.decoded_payloads
        );
        for (i, p) in self.problems.iter().enumerate() {
            if i > 0 {
                s.push(',');
            }
            s.push_str("{\"section\":");
            json_string(&mut s, p.section);
            match p.offset {
                Some(o) => {
                    let _ = write!(s, ",\"offset\":{o}");
                }
                None => s.push_str(",\"offset\":null"),
            }
            match p.tile {
                Some(t) => {
                    let _ = write!(s, ",\"tile\":{{\"lod\":{},\"x\":{},\"y\":{}}}", t.lod, t.x, t.y);
                }
                None => s.push_str(",\"tile\":null"),
            }
            s.push_str(",\"message\":");
            json_string(&mut s, &p.message);
            s.push('}');
        }
        s.push_str("]}");
        s
    }
}

/// `text` as a JSON string literal.
fn json_string(out: &mut String, text: &str) {
    out.push('"');
    for c in text.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if (c as u32) < 0x20 || c == '\u{2028}' || c == '\u{2029}' => {
                let _ = write!(out, "\\u{:04x}", c as u32);
            }
            c => out.push(c),
        }
    }
    out.push('"');
}

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.section)?;
        if let Some(o) = self.offset {
            write!(f, " at byte {o}")?;
        }
        if let Some(t) = self.tile {
            write!(f, ", tile (lod {}, x {}, y {})", t.lod, t.x, t.y)?;
        }
        write!(f, ": {}", self.message)
    }
}

impl fmt::Display for Report {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} bytes, content hash {:016x}, {} tiles (",
            self.path.display(),
            self.file_bytes,
            self.content_hash,
            self.tiles
        )?;
        let mut first = true;
        let named = KINDS.iter().map(|k| (k.name(), self.count(*k))).chain([("unknown", self.unknown_kinds)]);
        for (name, n) in named.filter(|(_, n)| *n > 0) {
            write!(f, "{}{n} {name}", if first { "" } else { ", " })?;
            first = false;
        }
        writeln!(f, ")")?;
        write!(
            f,
            "{} stored payloads, {} bytes; {} shared by deduplication; {} padding bytes",
            self.stored_payloads, self.payload_bytes, self.shared_payloads, self.padding_bytes
        )?;
        if self.decoded_payloads > 0 {
            write!(f, "; {} payloads decoded", self.decoded_payloads)?;
        }
        writeln!(f)?;
        if self.problems.is_empty() {
            return writeln!(f, "OK: no problem found");
        }
        writeln!(f, "{} problem{}:", self.problems.len(), if self.problems.len() == 1 { "" } else { "s" })?;
        for p in &self.problems {
            writeln!(f, "  {p}")?;
        }
        Ok(())
    }
}

/// A payload an entry points at (inside the data section, not empty): 24 bytes per payload
/// tile, the only memory `verify` needs in proportion to the pack.
#[derive(Clone, Copy)]
struct Payload {
    start: u64,
    len: u32,
    crc: u32,
    /// Index position of the entry.
    position: u64,
}

struct Verifier<'a> {
    pack: &'a Pack,
    b: &'a [u8],
    report: Report,
}

/// Checks all of `pack` (see the module documentation); never panics and allocates in
/// proportion to the index (one small record per payload), never to counts in the file.
pub fn verify(pack: &Pack, opts: VerifyOptions) -> Report {
    let h = pack.header();
    let report = Report {
        path: pack.path().to_path_buf(),
        file_bytes: pack.file().len() as u64,
        content_hash: h.content_hash,
        ..Report::default()
    };
    let mut v = Verifier { pack, b: pack.file(), report };
    v.sections();
    if let Err(e) = pack.check_index() {
        v.problem("index", Some(h.index_offset), None, e.to_string());
    }
    v.content_hash();
    v.levels();
    v.metadata();
    let payloads = v.entries();
    v.kinds_allowed();
    v.payloads(payloads, opts);
    // File order; problems without an offset first. The sort is stable: an entry's problems
    // stay in the order they were found.
    v.report.problems.sort_by_key(|p| p.offset.map_or(0, |o| o + 1));
    v.report
}

impl Verifier<'_> {
    fn problem(&mut self, section: &'static str, offset: Option<u64>, tile: Option<TileId>, message: String) {
        self.report.problems.push(Problem { offset, tile, section, message });
    }

    /// `start..end` is padding: counted, and every byte must be zero.
    fn zero(&mut self, start: u64, end: u64, what: &str) {
        if end <= start {
            return;
        }
        self.report.padding_bytes += end - start;
        let bytes = &self.b[start as usize..end as usize];
        if let Some(first) = bytes.iter().position(|b| *b != 0) {
            let n = bytes.iter().filter(|b| **b != 0).count();
            let message = format!(
                "{n} non-zero byte{} in the padding {what} ({start}..{end}): bytes no entry points at must be zero",
                if n == 1 { "" } else { "s" }
            );
            self.problem("padding", Some(start + first as u64), None, message);
        }
    }

    fn levels_len(&self) -> u64 {
        self.pack.header().description.level_count as u64 * LEVEL_LEN as u64
    }

    fn index_len(&self) -> u64 {
        self.pack.header().index_count * ENTRY_LEN as u64
    }

    /// The level table, index and metadata follow the header back to back (the spec fixes their
    /// offsets; `open` only needs them in order); bytes between sections are padding.
    fn sections(&mut self) {
        let h = *self.pack.header();
        let levels_end = h.levels_offset + self.levels_len();
        let index_end = h.index_offset + self.index_len();
        let meta_end = h.meta_offset + h.meta_len as u64;
        let fixed = [
            ("level table", h.levels_offset, HEADER_LEN as u64, format::at::LEVELS_OFFSET),
            ("index", h.index_offset, levels_end, format::at::INDEX_OFFSET),
            ("metadata", h.meta_offset, index_end, format::at::META_OFFSET),
        ];
        for (name, offset, expected, field) in fixed {
            if offset != expected {
                let message = format!("the {name} is at {offset}; it must follow the previous section, at {expected}");
                self.problem("header", Some(field as u64), None, message);
            }
        }
        self.zero(HEADER_LEN as u64, h.levels_offset, "between the header and the level table");
        self.zero(levels_end, h.index_offset, "between the level table and the index");
        self.zero(index_end, h.meta_offset, "between the index and the metadata");
        self.zero(meta_end, h.data_offset, "between the metadata and the data section");
    }

    /// FNV-1a 64 over the metadata, then the index bytes, as the writer computes it.
    fn content_hash(&mut self) {
        let h = self.pack.header();
        let index = &self.b[h.index_offset as usize..][..self.index_len() as usize];
        let hash = format::fnv1a(format::fnv1a(FNV_OFFSET, self.pack.metadata()), index);
        if hash != h.content_hash {
            let message =
                format!("content hash {:#018x}, but the metadata and index hash to {hash:#018x}", h.content_hash);
            self.problem("header", Some(format::at::CONTENT_HASH as u64), None, message);
        }
    }

    /// Each level's image size is `ceil(size / 2^lod)` and its tiles cover it.
    fn levels(&mut self) {
        let h = *self.pack.header();
        let d = h.description;
        let payload = d.tile_size as u64 - 2 * d.border as u64;
        for (lod, l) in self.pack.levels().iter().enumerate() {
            let at = h.levels_offset + (lod * LEVEL_LEN) as u64;
            let shrink = |v: u32| (v as u64 + (1u64 << lod) - 1) >> lod;
            let (w, h) = (shrink(d.width), shrink(d.height));
            if (l.width as u64, l.height as u64) != (w, h) {
                let message = format!(
                    "level {lod} says the image is {}x{}; {}x{} at LOD 0 gives {w}x{h}",
                    l.width, l.height, d.width, d.height
                );
                self.problem("levels", Some(at + 16), None, message);
            }
            if (l.tiles_w as u64) * payload < w || (l.tiles_h as u64) * payload < h {
                let message = format!(
                    "level {lod}: {}x{} tiles of {payload} texels (tile {} minus borders) do not cover {w}x{h} texels",
                    l.tiles_w, l.tiles_h, d.tile_size
                );
                self.problem("levels", Some(at), None, message);
            }
        }
    }

    fn metadata(&mut self) {
        if let Err(e) = std::str::from_utf8(self.pack.metadata()) {
            let at = self.pack.header().meta_offset + e.valid_up_to() as u64;
            self.problem("metadata", Some(at), None, "the metadata is not UTF-8 (JSON) text".into());
        }
    }

    /// Every index entry on its own; returns the payloads to check together.
    fn entries(&mut self) -> Vec<Payload> {
        let h = *self.pack.header();
        let d = h.description;
        let texel = d.channels as usize * d.sample_bytes as usize;
        let data = h.data_offset..h.data_offset + h.data_len;
        let mut payloads = Vec::new();
        let pack = self.pack;
        for (position, id) in pack.ids().enumerate() {
            let entry_at = h.index_offset + (position * ENTRY_LEN) as u64;
            let raw = &self.b[entry_at as usize..][..ENTRY_LEN];
            let e = Entry::decode(raw);
            let tile = Some(id);
            self.report.tiles += 1;
            if let Some(i) = raw[17..].iter().position(|b| *b != 0) {
                self.problem("index", Some(entry_at + 17 + i as u64), tile, "reserved entry bytes are not zero".into());
            }
            let Some(kind) = TileKind::from_u8(e.kind) else {
                self.report.unknown_kinds += 1;
                self.problem("index", Some(entry_at + 16), tile, format!("unknown tile kind {}", e.kind));
                continue;
            };
            self.report.kinds[kind as usize] += 1;
            match kind {
                TileKind::Absent => {
                    if let Some(i) = raw[..16].iter().position(|b| *b != 0) {
                        let message = "an absent entry's offset, length and checksum must be zero".into();
                        self.problem("index", Some(entry_at + i as u64), tile, message);
                    }
                }
                TileKind::Constant => {
                    if let Some(i) = raw[8..16].iter().position(|b| *b != 0) {
                        let message = "a constant entry's length and checksum must be zero".into();
                        self.problem("index", Some(entry_at + 8 + i as u64), tile, message);
                    }
                    if texel > 8 {
                        let message = format!("a constant tile, but a {texel}-byte texel does not fit an entry");
                        self.problem("index", Some(entry_at + 16), tile, message);
                    } else if let Some(i) = raw[texel..8].iter().position(|b| *b != 0) {
                        let message = format!("the bytes after the {texel}-byte constant value must be zero");
                        self.problem("index", Some(entry_at + (texel + i) as u64), tile, message);
                    }
                }
                _ => {
                    let (start, len) = (e.offset_or_value, e.len as u64);
                    let name = kind.name();
                    if len == 0 {
                        self.problem("index", Some(entry_at + 8), tile, format!("empty {name} payload"));
                        continue;
                    }
                    if start < data.start || start.checked_add(len).is_none_or(|end| end > data.end) {
                        let message = format!(
                            "{name} payload {start}+{len} lies outside the data section ({}..{})",
                            data.start, data.end
                        );
                        self.problem("index", Some(entry_at), tile, message);
                        continue;
                    }
                    if !start.is_multiple_of(h.payload_alignment as u64) {
                        let message = format!("payload at {start} is not aligned to {} bytes", h.payload_alignment);
                        self.problem("index", Some(entry_at), tile, message);
                    }
                    if let Some(expected) = stored_len(kind, &d).filter(|n| *n != len) {
                        let message = format!("a {name} tile is {expected} bytes, this payload {len}");
                        self.problem("index", Some(entry_at + 8), tile, message);
                    }
                    if matches!(kind, TileKind::Zstd | TileKind::ZstdDelta) {
                        let bytes = &self.b[start as usize..][..len as usize];
                        let raw_len = d.raw_tile_len();
                        match zstd::zstd_safe::get_frame_content_size(bytes) {
                            Ok(Some(n)) if Some(n) != raw_len => {
                                let message = format!(
                                    "the zstd frame holds {n} bytes; a raw tile is {}",
                                    raw_len.unwrap_or(u64::MAX)
                                );
                                self.problem("data", Some(start), tile, message);
                            }
                            Ok(_) => {}
                            Err(_) => self.problem(
                                "data",
                                Some(start),
                                tile,
                                "the payload does not start with a zstd frame header".into(),
                            ),
                        }
                    }
                    payloads.push(Payload { start, len: e.len, crc: e.crc, position: position as u64 });
                }
            }
        }
        payloads
    }

    /// Kinds the header does not allow, reported once per kind rather than per tile: BC blocks
    /// in a texture of another texel format or tile size, kinds newer than 1.0 without their
    /// required-feature bit.
    fn kinds_allowed(&mut self) {
        let h = *self.pack.header();
        let counts = self.report.kinds;
        for kind in TileKind::ALL.into_iter().filter(|k| counts[*k as usize] > 0) {
            let n = counts[kind as usize];
            if let Some(why) = h.description.refuses(kind) {
                let message = format!("{n} {} tile(s), but {why}", kind.name());
                self.problem("header", Some(format::at::TILE_SIZE as u64), None, message);
            }
            let bit = kind.required_feature();
            if h.required_features & bit != bit {
                let message = format!("{n} {} tile(s), but required-feature bit {bit:#x} is not set", kind.name());
                self.problem("header", Some(format::at::REQUIRED as u64), None, message);
            }
        }
    }

    /// The tile whose entry is at index `position`.
    fn id_of(&self, position: u64) -> TileId {
        let levels = self.pack.levels();
        let lod = levels.partition_point(|l| l.first_entry <= position).saturating_sub(1);
        let l = &levels[lod];
        let rel = position - l.first_entry;
        TileId { lod: lod as u32, x: (rel % l.tiles_w as u64) as u32, y: (rel / l.tiles_w as u64) as u32 }
    }

    /// The kind of the entry at `position`, known to be valid.
    #[cfg(feature = "decode")]
    fn kind_of(&self, position: u64) -> Option<TileKind> {
        let at = self.pack.header().index_offset as usize + position as usize * ENTRY_LEN + 16;
        TileKind::from_u8(self.b[at])
    }

    /// Checksums, exact-or-disjoint payload ranges, zero padding between them, and decoding.
    fn payloads(&mut self, mut payloads: Vec<Payload>, opts: VerifyOptions) {
        let h = *self.pack.header();
        let data_end = h.data_offset + h.data_len;
        payloads.sort_unstable_by_key(|p| (p.start, p.len, p.position));
        #[cfg(feature = "decode")]
        let mut decoder = opts.decode.then(PayloadDecoder::default);
        #[cfg(not(feature = "decode"))]
        let _ = opts;
        // End of the bytes covered so far and the payload reaching furthest.
        let mut covered = h.data_offset;
        let mut reach: Option<Payload> = None;
        let mut i = 0;
        while i < payloads.len() {
            let p = payloads[i];
            let group_len = payloads[i..].iter().take_while(|q| (q.start, q.len) == (p.start, p.len)).count();
            let group = &payloads[i..i + group_len];
            i += group_len;
            self.report.stored_payloads += 1;
            self.report.payload_bytes += p.len as u64;
            self.report.shared_payloads += group_len as u64 - 1;
            let end = p.start + p.len as u64;
            match reach {
                Some(r) if p.start < covered => {
                    let other = self.id_of(r.position);
                    let message = format!(
                        "payload {}+{} overlaps payload {}+{} of tile (lod {}, x {}, y {}); payloads may share bytes only whole",
                        p.start, p.len, r.start, r.len, other.lod, other.x, other.y
                    );
                    self.problem("data", Some(p.start), Some(self.id_of(p.position)), message);
                }
                _ => self.zero(covered, p.start, "between payloads"),
            }
            if end > covered {
                covered = end;
                reach = Some(p);
            }
            let bytes = &self.b[p.start as usize..end as usize];
            let crc = crc32c::crc32c(bytes);
            for q in group.iter().filter(|q| q.crc != crc) {
                let message =
                    format!("payload checksum mismatch: the entry says {:08x}, the bytes give {crc:08x}", q.crc);
                self.problem("data", Some(q.start), Some(self.id_of(q.position)), message);
            }
            #[cfg(feature = "decode")]
            if let Some(decoder) = decoder.as_mut() {
                self.decode(decoder, group, bytes, crc);
            }
        }
        self.zero(covered, data_end, "after the last payload");
    }

    /// Decodes the payload `bytes` shared by `group` once for each kind its entries read it as;
    /// not for entries whose checksum (`crc` is the bytes') already failed.
    #[cfg(feature = "decode")]
    fn decode(&mut self, decoder: &mut PayloadDecoder, group: &[Payload], bytes: &[u8], crc: u32) {
        let d = self.pack.header().description;
        let max_bytes = self.pack.limits().max_decoded_bytes;
        let mut done = [false; TileKind::ALL.len()];
        for q in group.iter().filter(|q| q.crc == crc) {
            // Entries of unknown kinds were reported by `entries()` and carry no payload.
            let Some(kind) = self.kind_of(q.position) else { continue };
            // A raw or block payload of the wrong size, or block kinds the texture's format
            // does not allow, are already reported.
            if std::mem::replace(&mut done[kind as usize], true)
                || stored_len(kind, &d).is_some_and(|n| n != q.len as u64)
                || d.refuses(kind).is_some()
            {
                continue;
            }
            self.report.decoded_payloads += 1;
            if let Err(m) = decoder.decode(kind, bytes, &d, max_bytes) {
                let message = format!("{} payload does not decode to one tile: {m}", kind.name());
                self.problem("data", Some(q.start), Some(self.id_of(q.position)), message);
            }
        }
    }
}

/// Bytes of a payload whose size the format fixes: raw texels, BC1 and BC7 blocks.
fn stored_len(kind: TileKind, d: &Description) -> Option<u64> {
    match kind {
        TileKind::Raw => Some(d.raw_tile_len().unwrap_or(u64::MAX)),
        _ => d.block_tile_len(kind),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn json_strings_are_escaped() {
        let mut s = String::new();
        json_string(&mut s, "a\"b\\c\nd\u{1}e\u{2028}é");
        assert_eq!(s, r#""a\"b\\c\nd\u0001e\u2028é""#);
    }
}
