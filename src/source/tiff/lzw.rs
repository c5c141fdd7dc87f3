//! TIFF's LZW, decoded straight into the strip's buffer, or a piece at a time ([`Stream`]).
//!
//! TIFF LZW (compression 5) packs codes most significant bit first, 9 to 12 bits wide, with
//! 256 the clear code and 257 the end of the strip, and widens the codes one code early (at
//! 511, 1023 and 2047 entries rather than 512, 1024, 2048). Every string a code stands for
//! is one that was written before, whole, in the output: the string a new code adds is the
//! previous code's string and the first byte of the current one, which follow each other in
//! the output. So the table holds where each string starts in the output and how long it is,
//! and decoding a code is a copy from earlier in the buffer, as an LZ77 decoder's is: no
//! chains of prefixes are walked, and short strings are copied 16 bytes at a time into the
//! room the buffer has left. On the 16384² LZW benchmark (`bench/split-matrix.sh`, JPEG tiles)
//! `split` went from 23.2 to 18.1 CPU milliseconds per source megapixel, where the `weezl`
//! decoder through the `tiff` crate had been 58% of its CPU (issue 28, docs/benchmarks.md).
//!
//! The old-style, bit-reversed LZW of libtiff before 5.0 is not read here (the `tiff` crate
//! refuses it as well).

/// Codes with a meaning of their own.
const CLEAR: u16 = 256;
const END: u16 = 257;
/// The first code the table assigns, and one past the last a 12-bit code can name.
const FIRST: usize = 258;
const TABLE: usize = 4096;

/// Bytes copied at once for a short string, into room the output has past the string.
const WIDE: usize = 16;

/// Why a strip cannot be decoded.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum LzwError {
    /// A code names an entry that does not exist yet.
    BadCode { code: u16, at_byte: usize },
    /// The data ends before the strip is full and without an end code.
    Truncated { decoded: usize },
    /// The first code after a clear code is not a byte.
    NoLiteralAfterClear { at_byte: usize },
    /// The data could not be read.
    Read(String),
}

impl std::fmt::Display for LzwError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LzwError::BadCode { code, at_byte } => write!(f, "LZW code {code} at byte {at_byte} names no string yet"),
            LzwError::Truncated { decoded } => {
                write!(f, "the LZW data ends after {decoded} bytes of the strip, without an end code")
            }
            LzwError::NoLiteralAfterClear { at_byte } => {
                write!(f, "the LZW code after a clear code at byte {at_byte} is not a byte value")
            }
            LzwError::Read(e) => write!(f, "cannot read the strip: {e}"),
        }
    }
}

/// Bytes of compressed data read from the file at once: the strip is never held whole (a
/// 128-row strip of a 16384-texel RGB image is megabytes, per decoding worker).
const READ: usize = 64 << 10;

/// Reads codes most significant bit first from `input`, [`READ`] bytes at a time.
struct Bits<R> {
    input: R,
    /// Bytes read and not yet loaded from `next` on; `base` bytes of the input came before.
    data: Vec<u8>,
    next: usize,
    base: usize,
    /// Loaded bits, the oldest at the top; `count` of them are valid.
    buffer: u64,
    count: u32,
    /// The input has no more, or failed (`error`).
    done: bool,
    error: Option<std::io::Error>,
}

impl<R: std::io::Read> Bits<R> {
    fn new(input: R) -> Bits<R> {
        Bits { input, data: Vec::with_capacity(READ), next: 0, base: 0, buffer: 0, count: 0, done: false, error: None }
    }

    /// The next `width`-bit code, or `None` once the input is used up.
    #[inline]
    fn code(&mut self, width: u32) -> Option<u16> {
        if self.count < width {
            self.refill();
            if self.count < width {
                return None;
            }
        }
        let code = (self.buffer >> (64 - width)) as u16;
        self.buffer <<= width;
        self.count -= width;
        Some(code)
    }

    #[inline]
    fn refill(&mut self) {
        if self.data.len() - self.next < 8 && !self.done {
            self.read_more();
        }
        if let Some(bytes) = self.data.get(self.next..self.next + 8) {
            // Whole bytes only: up to 7 of the 8 fit beside the bits left over.
            let take = (64 - self.count) / 8;
            let word = u64::from_be_bytes(bytes.try_into().unwrap_or([0; 8]));
            let word = if take == 8 { word } else { word >> (64 - 8 * take) << (64 - 8 * take) };
            self.buffer |= word >> self.count;
            self.count += 8 * take;
            self.next += take as usize;
        } else {
            while self.count <= 56 && self.next < self.data.len() {
                self.buffer |= (self.data[self.next] as u64) << (56 - self.count);
                self.count += 8;
                self.next += 1;
            }
        }
    }

    /// Moves the bytes not yet loaded to the front and reads after them.
    #[cold]
    fn read_more(&mut self) {
        self.data.drain(..self.next);
        self.base += self.next;
        self.next = 0;
        let have = self.data.len();
        self.data.resize(READ, 0);
        let read = loop {
            match self.input.read(&mut self.data[have..]) {
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                other => break other,
            }
        };
        let got = read.unwrap_or_else(|e| {
            self.error = Some(e);
            0
        });
        self.done = got == 0;
        self.data.truncate(have + got);
    }

    /// Byte offset of the code about to be read, for error messages.
    fn position(&self) -> usize {
        self.base + self.next - (self.count / 8) as usize
    }
}

/// Decodes the LZW data `input` gives into `out`, which it fills exactly: decoding stops once
/// `out` is full (data past that, and a missing end code then, are ignored, as libtiff does),
/// and fails if the data ends first.
pub(crate) fn decode(input: impl std::io::Read, out: &mut [u8]) -> Result<(), LzwError> {
    let mut pos = 0;
    Codes::new().run(&mut Bits::new(input), out, &mut pos, out.len(), false)
}

/// The decoder's state between codes: the table and the string written last.
struct Codes {
    /// Per code: where its string starts in the output, and its length.
    table: Vec<(u32, u32)>,
    width: u32,
    next_code: usize,
    /// The string written last: where it starts and how long it is (0: none since a clear).
    prev_start: usize,
    prev_len: usize,
    /// The longest string in the table, and where the output stood at the last clear code:
    /// no code names a string before it.
    longest: usize,
    since_clear: usize,
}

impl Codes {
    fn new() -> Codes {
        Codes {
            table: vec![(0, 0); TABLE],
            width: 9,
            next_code: FIRST,
            prev_start: 0,
            prev_len: 0,
            longest: 1,
            since_clear: 0,
        }
    }

    /// Decodes codes into `out` from `*pos` on while `*pos < stop`; with `keep_room`, also
    /// only while `out` has room past `*pos` for the longest string a code can name (and
    /// [`WIDE`] bytes), else strings are cut at the end of `out` (the end of the strip).
    fn run<R: std::io::Read>(
        &mut self,
        bits: &mut Bits<R>,
        out: &mut [u8],
        pos: &mut usize,
        stop: usize,
        keep_room: bool,
    ) -> Result<(), LzwError> {
        let Codes { table, width, next_code, prev_start, prev_len, longest, since_clear } = self;
        while *pos < stop && (!keep_room || *pos + *longest + 1 + WIDE <= out.len()) {
            let at_byte = bits.position();
            let Some(code) = bits.code(*width) else {
                return Err(match bits.error.take() {
                    Some(e) => LzwError::Read(e.to_string()),
                    None => LzwError::Truncated { decoded: *pos },
                });
            };
            if code == CLEAR {
                (*width, *next_code, *prev_len, *longest, *since_clear) = (9, FIRST, 0, 1, *pos);
                continue;
            }
            if code == END {
                return Err(LzwError::Truncated { decoded: *pos });
            }
            let code = code as usize;
            let n = if code < 256 {
                out[*pos] = code as u8;
                1
            } else if *prev_len == 0 {
                return Err(LzwError::NoLiteralAfterClear { at_byte });
            } else if code < *next_code {
                let (src, n) = table[code];
                copy_earlier(out, src as usize, n as usize, *pos);
                n as usize
            } else if code == *next_code {
                // The string being defined right now: the previous one and its own first byte.
                copy_earlier(out, *prev_start, *prev_len, *pos);
                if *pos + *prev_len < out.len() {
                    out[*pos + *prev_len] = out[*prev_start];
                }
                *prev_len + 1
            } else {
                return Err(LzwError::BadCode { code: code as u16, at_byte });
            };
            if *prev_len > 0 && *next_code < TABLE {
                // The previous string and this one's first byte, which follow it in the output.
                table[*next_code] = (*prev_start as u32, *prev_len as u32 + 1);
                *longest = (*longest).max(*prev_len + 1);
                *next_code += 1;
                if *next_code + 1 >= 1 << *width && *width < 12 {
                    *width += 1;
                }
            }
            // The next entry starts where this string was just written.
            (*prev_start, *prev_len) = (*pos, n);
            *pos += n;
        }
        Ok(())
    }

    /// Every position `by` bytes earlier: the output before them was dropped.
    fn shift(&mut self, by: usize) {
        for entry in &mut self.table[FIRST..self.next_code] {
            entry.0 -= by as u32;
        }
        self.prev_start -= by.min(self.prev_start);
        self.since_clear -= by;
    }
}

/// One LZW strip decoded in pieces: a code is a copy of a string written before, so the
/// strings since the last clear code (all a code can name: tens of KiB on photographs, more on
/// long runs of one colour) are kept in a window with what has not been handed out yet.
pub(crate) struct Stream<R> {
    bits: Bits<R>,
    codes: Codes,
    window: Vec<u8>,
    /// Bytes decoded into `window`, and the first of them not handed out yet.
    pos: usize,
    out_at: usize,
    /// Bytes of the strip before `window[0]` (dropped).
    base: usize,
}

/// The window's first size: a few pieces of rows, so that moving the strings kept to its front
/// (when it is full) is rare.
const WINDOW: usize = 512 << 10;

impl<R: std::io::Read> Stream<R> {
    /// The strip `input` holds, reusing `window` (of [`WINDOW`] bytes where it is empty).
    pub fn new(input: R, mut window: Vec<u8>) -> Stream<R> {
        if window.is_empty() {
            window.resize(WINDOW, 0);
        }
        Stream { bits: Bits::new(input), codes: Codes::new(), window, pos: 0, out_at: 0, base: 0 }
    }

    /// The window, for the next strip.
    pub fn into_window(self) -> Vec<u8> {
        self.window
    }

    pub fn window_bytes(&self) -> usize {
        self.window.capacity()
    }

    /// The strip's next `out.len()` bytes: codes are decoded only as far as they give (as
    /// [`decode`] stops at the end of the strip, whatever follows).
    pub fn fill(&mut self, out: &mut [u8]) -> Result<(), LzwError> {
        let mut done = 0;
        loop {
            let n = (self.pos - self.out_at).min(out.len() - done);
            out[done..done + n].copy_from_slice(&self.window[self.out_at..self.out_at + n]);
            (self.out_at, done) = (self.out_at + n, done + n);
            if done == out.len() {
                return Ok(());
            }
            self.make_room();
            let stop = self.out_at + out.len() - done;
            let base = self.base;
            self.codes.run(&mut self.bits, &mut self.window, &mut self.pos, stop, true).map_err(|e| match e {
                LzwError::Truncated { decoded } => LzwError::Truncated { decoded: base + decoded },
                e => e,
            })?;
        }
    }

    /// Drops what no code can name and is handed out, and grows the window if the longest
    /// string would still not fit.
    fn make_room(&mut self) {
        let need = self.codes.longest + 1 + WIDE;
        if self.pos + need <= self.window.len() {
            return;
        }
        let keep = self.codes.since_clear.min(self.out_at);
        self.window.copy_within(keep..self.pos, 0);
        self.codes.shift(keep);
        (self.pos, self.out_at, self.base) = (self.pos - keep, self.out_at - keep, self.base + keep);
        if self.pos + need > self.window.len() {
            self.window.resize((2 * self.window.len()).max(self.pos + need), 0);
        }
    }
}

/// `out[pos..pos + n] = out[src..src + n]` (`src + n <= pos`), as far as `out` goes; short
/// strings are copied [`WIDE`] bytes at once (one load and one store, no call) where `out` has
/// the room, the bytes past `n` being overwritten by the strings that follow.
#[inline(always)]
fn copy_earlier(out: &mut [u8], src: usize, n: usize, pos: usize) {
    if n <= WIDE && pos + WIDE <= out.len() {
        let mut wide = [0u8; WIDE];
        wide.copy_from_slice(&out[src..src + WIDE]);
        out[pos..pos + WIDE].copy_from_slice(&wide);
    } else {
        let n = n.min(out.len() - pos);
        out.copy_within(src..src + n, pos);
    }
}

/// Where the LZW or Deflate strips of a TIFF lie and how their rows are stored: for strips
/// that hold the texels as the `tiff` crate delivers them (every stored sample, 8 or 16 bits,
/// no WhiteIsZero inversion), a [`StripReader`] gives the bytes the crate's `read_chunk_bytes`
/// would: LZW from a decoder several times faster, a strip at a time; Deflate as a stream, in
/// pieces of rows (`strips_ahead`: the strip is never held whole).
pub(crate) struct OwnStrips {
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
    /// Bytes of one row of the image, and samples per texel.
    pub row_bytes: usize,
    pub samples: usize,
    pub sixteen_bit: bool,
    pub big_endian: bool,
    /// The horizontal predictor (2) is undone after decoding.
    pub predictor: bool,
    /// Deflate (compression 8 or 32946), not LZW.
    pub deflate: bool,
}

impl OwnStrips {
    /// The most a worker holds of its own between pieces ([`StripReader`]'s `held_bytes`) on
    /// strips of `strip_bytes` decoded bytes: an LZW window never holds more than the strip
    /// and one string past it, and grows by doubling; Deflate keeps none.
    pub fn worker_bytes_at_most(&self, strip_bytes: u64) -> u64 {
        match self.deflate {
            true => 0,
            false => (WINDOW as u64).max(strip_bytes.saturating_add((TABLE + 1 + WIDE) as u64).saturating_mul(2)),
        }
    }

    /// 16-bit samples into native byte order and the predictor undone, on whole rows.
    fn as_delivered(&self, rows: &mut [u8]) {
        for row in rows.chunks_exact_mut(self.row_bytes) {
            if self.sixteen_bit {
                undo_predictor_16(row, self.samples, self.big_endian, self.predictor);
            } else if self.predictor {
                match self.samples {
                    1 => undo_predictor_8::<1>(row),
                    2 => undo_predictor_8::<2>(row),
                    3 => undo_predictor_8::<3>(row),
                    4 => undo_predictor_8::<4>(row),
                    n => {
                        for i in n..row.len() {
                            row[i] = row[i].wrapping_add(row[i - n]);
                        }
                    }
                }
            }
        }
    }
}

/// One worker's reader of [`OwnStrips`], with a file handle of its own.
pub(crate) struct StripReader {
    file: std::sync::Arc<std::fs::File>,
    strips: std::sync::Arc<OwnStrips>,
    /// The strip begun, as a stream at the next piece; an LZW stream's window, between strips.
    strip: Strip,
    window: Vec<u8>,
}

enum Strip {
    None,
    Lzw(Stream<Span>),
    Deflate(flate2::read::ZlibDecoder<Span>),
}

/// `left` bytes of `file` from `offset` on, as a reader; a file that ends before them is an
/// error, not the end of the strip.
struct Span {
    file: std::sync::Arc<std::fs::File>,
    offset: u64,
    left: u64,
}

impl std::io::Read for Span {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        use std::os::unix::fs::FileExt;
        let want = buf.len().min(usize::try_from(self.left).unwrap_or(usize::MAX));
        if want == 0 {
            return Ok(0);
        }
        let got = self.file.read_at(&mut buf[..want], self.offset)?;
        if got == 0 {
            return Err(std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "the file ends early (truncated TIFF)"));
        }
        self.offset += got as u64;
        self.left -= got as u64;
        Ok(got)
    }
}

impl StripReader {
    pub fn new(file: std::fs::File, strips: std::sync::Arc<OwnStrips>) -> StripReader {
        StripReader { file: std::sync::Arc::new(file), strips, strip: Strip::None, window: Vec::new() }
    }

    /// The compressed bytes of strip `strip`.
    fn span(&self, strip: u32) -> Result<Span, String> {
        let s = &*self.strips;
        match (s.offsets.get(strip as usize), s.counts.get(strip as usize)) {
            (Some(&offset), Some(&left)) => Ok(Span { file: std::sync::Arc::clone(&self.file), offset, left }),
            _ => Err(format!("strip {strip} has no offset or byte count")),
        }
    }
}

impl super::strips_ahead::StripDecoder for StripReader {
    fn begin(&mut self, strip: u32) -> Result<(), String> {
        if let Strip::Lzw(stream) = std::mem::replace(&mut self.strip, Strip::None) {
            self.window = stream.into_window();
        }
        let span = self.span(strip)?;
        self.strip = match self.strips.deflate {
            true => Strip::Deflate(flate2::read::ZlibDecoder::new(span)),
            false => Strip::Lzw(Stream::new(span, std::mem::take(&mut self.window))),
        };
        Ok(())
    }

    /// The next rows of the strip begun.
    fn fill(&mut self, out: &mut [u8]) -> Result<(), String> {
        match &mut self.strip {
            Strip::Deflate(inflate) => std::io::Read::read_exact(inflate, out).map_err(|e| match e.kind() {
                std::io::ErrorKind::UnexpectedEof => format!("the Deflate data ends before the strip is full: {e}"),
                _ => format!("corrupt or undecodable TIFF data: deflate: {e}"),
            })?,
            Strip::Lzw(stream) => stream.fill(out).map_err(|e| format!("corrupt or undecodable TIFF data: {e}"))?,
            Strip::None => return Err("no strip begun".into()),
        }
        self.strips.as_delivered(out);
        Ok(())
    }

    /// An LZW stream's window (the strings since its last clear code).
    fn held_bytes(&self) -> u64 {
        match &self.strip {
            Strip::Lzw(stream) => stream.window_bytes() as u64,
            _ => self.window.capacity() as u64,
        }
    }
}

/// The horizontal predictor undone on a row of `S`-sample 8-bit texels: each sample is the
/// difference from the one a texel before. The running texel is kept in registers, not read
/// back from the row just written (a chain through memory that cost a tenth of the decoding).
fn undo_predictor_8<const S: usize>(row: &mut [u8]) {
    let mut texel = [0u8; S];
    for px in row.chunks_exact_mut(S) {
        for c in 0..S {
            texel[c] = texel[c].wrapping_add(px[c]);
            px[c] = texel[c];
        }
    }
}

/// 16-bit samples of one row into native byte order, and the horizontal predictor undone.
pub(super) fn undo_predictor_16(row: &mut [u8], samples: usize, big_endian: bool, predictor: bool) {
    let read = |b: &[u8]| if big_endian { u16::from_be_bytes([b[0], b[1]]) } else { u16::from_le_bytes([b[0], b[1]]) };
    let stride = 2 * samples;
    for i in (0..row.len()).step_by(2) {
        let mut v = read(&row[i..]);
        if predictor && i >= stride {
            v = v.wrapping_add(u16::from_ne_bytes([row[i - stride], row[i - stride + 1]]));
        }
        row[i..i + 2].copy_from_slice(&v.to_ne_bytes());
    }
}

#[cfg(test)]
mod tests {
    use super::super::strips_ahead::StripDecoder;
    use super::*;

    /// A TIFF LZW encoder written from the specification for these tests alone: a dictionary
    /// keyed by (prefix code, byte), a clear code at the start and when the table fills, codes
    /// widened one code early. (The decoder is also checked against `weezl`, below.)
    fn encode(input: &[u8], clear_every: Option<usize>) -> Vec<u8> {
        use std::collections::HashMap;
        let mut out = Vec::new();
        let (mut acc, mut nbits) = (0u64, 0u32);
        let mut put = |code: u16, width: u32, out: &mut Vec<u8>| {
            acc = (acc << width) | code as u64;
            nbits += width;
            while nbits >= 8 {
                out.push((acc >> (nbits - 8)) as u8);
                nbits -= 8;
            }
        };
        let mut dict: HashMap<(u16, u8), u16> = HashMap::new();
        let mut width = 9;
        let mut next = FIRST as u16;
        put(CLEAR, width, &mut out);
        let mut current: Option<u16> = None;
        let mut since_clear = 0;
        for &b in input {
            let Some(c) = current else {
                current = Some(b as u16);
                continue;
            };
            if let Some(&code) = dict.get(&(c, b)) {
                current = Some(code);
                continue;
            }
            put(c, width, &mut out);
            dict.insert((c, b), next);
            next += 1;
            since_clear += 1;
            // The decoder adds this entry one code later, and widens when its table is one
            // short of the next power of two.
            if next as usize >= 1 << width && width < 12 {
                width += 1;
            }
            if next as usize >= TABLE - 2 || clear_every.is_some_and(|n| since_clear >= n) {
                put(CLEAR, width, &mut out);
                dict.clear();
                width = 9;
                next = FIRST as u16;
                since_clear = 0;
            }
            current = Some(b as u16);
        }
        if let Some(c) = current {
            put(c, width, &mut out);
            // The end code's width counts the entry the decoder adds on reading `c`.
            if next as usize + 1 >= 1 << width && width < 12 {
                width += 1;
            }
        }
        put(END, width, &mut out);
        if nbits > 0 {
            out.push((acc << (8 - nbits)) as u8);
        }
        out
    }

    fn inputs() -> Vec<Vec<u8>> {
        let mut state = 0x1234_5678u32;
        let mut noise = |n: usize, span: u32| -> Vec<u8> {
            (0..n)
                .map(|_| {
                    state ^= state << 13;
                    state ^= state >> 17;
                    state ^= state << 5;
                    (state % span) as u8
                })
                .collect()
        };
        vec![
            vec![7],
            vec![0; 100_000],                                  // one long run: KwKwK codes
            b"abababababababababab".to_vec(),                  // KwKwK after a few entries
            noise(70_000, 256),                                // fills the table, clears
            noise(50_000, 4),                                  // long strings from few bytes
            (0..60_000u32).map(|i| (i / 300) as u8).collect(), // runs, a gradient's steps
        ]
    }

    #[test]
    fn decodes_what_an_encoder_from_the_specification_writes() {
        for input in inputs() {
            for clear in [None, Some(100)] {
                let data = encode(&input, clear);
                let mut out = vec![0xAA; input.len()];
                decode(&data[..], &mut out).unwrap();
                assert!(out == input, "{} bytes, clear {clear:?}", input.len());
            }
        }
    }

    #[test]
    fn a_stream_gives_the_strip_in_pieces_of_any_size() {
        for input in inputs() {
            for clear in [None, Some(100)] {
                let data = encode(&input, clear);
                // Windows of 64 and 300 bytes: the strings kept are moved and the window grows.
                for (piece, window) in [(1, 64), (7, 64), (1000, 300), (100_000, 0)] {
                    let mut stream = Stream::new(&data[..], vec![0; window]);
                    let mut got = Vec::new();
                    while got.len() < input.len() {
                        let mut out = vec![0xAA; piece.min(input.len() - got.len())];
                        stream.fill(&mut out).unwrap();
                        got.extend_from_slice(&out);
                    }
                    assert!(got == input, "{} bytes, clear {clear:?}, pieces of {piece}", input.len());
                }
                let mut stream = Stream::new(&data[..data.len() / 2], Vec::new());
                let mut whole = vec![0; input.len()];
                if input.len() > 100 {
                    assert!(matches!(stream.fill(&mut whole), Err(LzwError::Truncated { .. })));
                }
            }
        }
    }

    #[test]
    fn agrees_with_weezl() {
        for input in inputs() {
            let data = weezl::encode::Encoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8).encode(&input).unwrap();
            let mut out = vec![0; input.len()];
            decode(&data[..], &mut out).unwrap();
            assert!(out == input, "weezl's encoding of {} bytes", input.len());
        }
    }

    #[test]
    fn stops_when_the_strip_is_full_and_fails_when_data_runs_out() {
        let input: Vec<u8> = (0..5000u32).map(|i| (i % 97) as u8).collect();
        let data = encode(&input, None);
        let mut part = vec![0; 3000];
        decode(&data[..], &mut part).unwrap();
        assert_eq!(part, input[..3000]);
        let mut more = vec![0; 6000];
        assert!(matches!(decode(&data[..], &mut more), Err(LzwError::Truncated { decoded: 5000 })));
        let mut whole = vec![0; 5000];
        assert!(matches!(decode(&data[..data.len() / 2], &mut whole), Err(LzwError::Truncated { .. })));
    }

    /// Writes an LZW TIFF of `C` texels in 5-row strips with the `tiff` crate's encoder.
    fn write_tiff<C: tiff::encoder::colortype::ColorType>(path: &std::path::Path, w: u32, h: u32, data: &[C::Inner])
    where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        use tiff::encoder::{Compression, Predictor, TiffEncoder};
        let file = std::fs::File::create(path).unwrap();
        let mut tiff =
            TiffEncoder::new(file).unwrap().with_compression(Compression::Lzw).with_predictor(Predictor::Horizontal);
        let mut image = tiff.new_image::<C>(w, h).unwrap();
        image.rows_per_strip(5).unwrap();
        image.write_data(data).unwrap();
    }

    /// Every strip of `path` as our reader and as the `tiff` crate's `read_chunk_bytes` give it.
    fn compare_strips(path: &std::path::Path, samples: usize, sixteen_bit: bool) {
        use tiff::tags::Tag;
        let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
        let (w, h) = decoder.dimensions().unwrap();
        let row_bytes = w as usize * samples * if sixteen_bit { 2 } else { 1 };
        let strips = OwnStrips {
            offsets: decoder.get_tag_u64_vec(Tag::StripOffsets).unwrap(),
            counts: decoder.get_tag_u64_vec(Tag::StripByteCounts).unwrap(),
            row_bytes,
            samples,
            sixteen_bit,
            big_endian: false,
            predictor: true,
            deflate: false,
        };
        let file = std::fs::File::open(path).unwrap();
        let mut reader = StripReader::new(file, std::sync::Arc::new(strips));
        for strip in 0..h.div_ceil(5) {
            let len = row_bytes * 5.min(h - strip * 5) as usize;
            let (mut ours, mut theirs) = (vec![0u8; len], vec![0u8; len]);
            reader.begin(strip).and_then(|()| reader.fill(&mut ours)).unwrap();
            decoder.read_chunk_bytes(strip, &mut theirs).unwrap();
            assert!(ours == theirs, "{}: strip {strip}", path.display());
        }
    }

    #[test]
    fn strips_match_the_tiff_crate_with_the_predictor() {
        use tiff::encoder::colortype::{Gray8, Gray16, RGB8, RGBA8};
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (37u32, 23u32);
        let values = |n: usize| -> Vec<u32> { (0..n as u32).map(|i| i.wrapping_mul(2_654_435_761) >> 7).collect() };
        let n = (w * h) as usize;
        let path = dir.path().join("rgb8.tif");
        write_tiff::<RGB8>(&path, w, h, &values(n * 3).iter().map(|v| *v as u8).collect::<Vec<_>>());
        compare_strips(&path, 3, false);
        let path = dir.path().join("rgba8.tif");
        write_tiff::<RGBA8>(&path, w, h, &values(n * 4).iter().map(|v| (*v % 7) as u8).collect::<Vec<_>>());
        compare_strips(&path, 4, false);
        let path = dir.path().join("grey8.tif");
        write_tiff::<Gray8>(&path, w, h, &values(n).iter().map(|v| *v as u8).collect::<Vec<_>>());
        compare_strips(&path, 1, false);
        let path = dir.path().join("grey16.tif");
        write_tiff::<Gray16>(&path, w, h, &values(n).iter().map(|v| *v as u16).collect::<Vec<_>>());
        compare_strips(&path, 1, true);
    }

    #[test]
    fn codes_not_yet_defined_are_refused() {
        // Clear, then code 300 (9 bits): nothing is defined yet.
        let data = [0x80, 0x4B, 0x00, 0x00];
        let mut out = vec![0; 10];
        assert!(matches!(decode(&data[..], &mut out), Err(LzwError::NoLiteralAfterClear { .. })));
        // Clear, 'a', then code 400.
        let mut bits = 0u64;
        for (code, _) in [(256u64, 9), (97, 9), (400, 9)] {
            bits = (bits << 9) | code;
        }
        let bytes = (bits << (64 - 27)).to_be_bytes();
        assert!(matches!(decode(&bytes[..], &mut out), Err(LzwError::BadCode { code: 400, .. })));
    }
}
