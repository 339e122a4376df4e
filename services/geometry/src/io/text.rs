//! Byte-level helpers shared by the text formats: ascii PLY, OBJ and ascii STL.
//!
//! The readers work on bytes, not `str`: a stray non-UTF-8 byte in a comment or an object name
//! must not stop a mesh from loading, and only the tokens that carry numbers need to be text.

/// The lines of a text with their 1-based numbers. A line ends at `\n`, `\r\n` or a lone `\r`
/// (files from Unix, Windows and classic Mac OS); the terminator is not part of the line.
pub(super) struct Lines<'a> {
    bytes: &'a [u8],
    offset: usize,
    next_number: usize,
}

impl<'a> Lines<'a> {
    /// The lines of `bytes`, the first numbered `first_number`.
    pub fn numbered_from(bytes: &'a [u8], first_number: usize) -> Self {
        Self {
            bytes,
            offset: 0,
            next_number: first_number,
        }
    }

    /// Byte offset, into the text given to [`Lines::numbered_from`], of the first unread byte.
    pub fn offset(&self) -> usize {
        self.offset
    }

    /// Number the next line will have (one past the last line at the end of the text).
    pub fn next_number(&self) -> usize {
        self.next_number
    }

    /// Bytes not yet returned.
    pub fn remaining_bytes(&self) -> usize {
        self.bytes.len() - self.offset
    }
}

impl<'a> Iterator for Lines<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        let rest = self
            .bytes
            .get(self.offset..)
            .filter(|rest| !rest.is_empty())?;
        let (line, consumed) = match rest.iter().position(|&b| b == b'\n' || b == b'\r') {
            Some(end) => {
                let crlf = rest[end] == b'\r' && rest.get(end + 1) == Some(&b'\n');
                (&rest[..end], end + 1 + usize::from(crlf))
            }
            None => (rest, rest.len()),
        };
        self.offset += consumed;
        let number = self.next_number;
        self.next_number += 1;
        Some((number, line))
    }
}

/// Splits the next whitespace-separated token off the front of `rest`.
pub(super) fn next_token<'a>(rest: &mut &'a [u8]) -> Option<&'a [u8]> {
    let start = rest.iter().position(|b| !b.is_ascii_whitespace())?;
    let tail = &rest[start..];
    let end = tail
        .iter()
        .position(|b| b.is_ascii_whitespace())
        .unwrap_or(tail.len());
    *rest = &tail[end..];
    Some(&tail[..end])
}

/// The whitespace-separated tokens of one line.
pub(super) fn tokens(line: &[u8]) -> impl Iterator<Item = &[u8]> {
    line.split(|b| b.is_ascii_whitespace())
        .filter(|token| !token.is_empty())
}

/// Whether a line holds nothing but whitespace.
pub(super) fn is_blank(line: &[u8]) -> bool {
    line.iter().all(|b| b.is_ascii_whitespace())
}

/// A token read as a real number; `nan` and `inf` are accepted here and rejected by mesh
/// validation, which can say which vertex is at fault.
pub(super) fn parse_f64(token: &[u8]) -> Option<f64> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

/// A token read as a signed integer.
pub(super) fn parse_i64(token: &[u8]) -> Option<i64> {
    std::str::from_utf8(token).ok()?.parse().ok()
}

/// Whether `token` is `keyword`, ignoring ASCII case (some exporters shout `SOLID`).
pub(super) fn is_keyword(token: &[u8], keyword: &str) -> bool {
    token.eq_ignore_ascii_case(keyword.as_bytes())
}

/// Longest quotation of file content in an error message, in characters.
const QUOTE_MAX_CHARS: usize = 40;

/// File content as an error message quotes it: backquoted, invalid UTF-8 replaced, control
/// characters escaped, cut at [`QUOTE_MAX_CHARS`] characters.
pub(super) fn quote(bytes: &[u8]) -> String {
    let text = String::from_utf8_lossy(bytes);
    let mut quoted = String::from("`");
    for (i, c) in text.chars().enumerate() {
        if i == QUOTE_MAX_CHARS {
            quoted.push('…');
            break;
        }
        if c.is_control() {
            quoted.extend(c.escape_default());
        } else {
            quoted.push(c);
        }
    }
    quoted.push('`');
    quoted
}

/// Whitespace-separated tokens across lines, each with its line number; ascii STL is a
/// keyword stream in which line breaks carry no meaning except after `solid` names.
pub(super) struct Tokens<'a> {
    lines: Lines<'a>,
    rest_of_line: &'a [u8],
    line: usize,
}

impl<'a> Tokens<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self {
            lines: Lines::numbered_from(bytes, 1),
            rest_of_line: &[],
            line: 1,
        }
    }

    /// The line of the last token returned (or of the last line read, at the end).
    pub fn line(&self) -> usize {
        self.line
    }

    /// Drops what is left of the current line (a solid's name, say).
    pub fn skip_rest_of_line(&mut self) {
        self.rest_of_line = &[];
    }
}

impl<'a> Iterator for Tokens<'a> {
    type Item = (usize, &'a [u8]);

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(token) = next_token(&mut self.rest_of_line) {
                return Some((self.line, token));
            }
            let (number, line) = self.lines.next()?;
            self.line = number;
            self.rest_of_line = line;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lines_end_at_lf_crlf_and_lone_cr() {
        let text = b"a\nb\r\nc\rd";
        let lines: Vec<_> = Lines::numbered_from(text, 1).collect();
        assert_eq!(
            lines,
            vec![
                (1, &b"a"[..]),
                (2, &b"b"[..]),
                (3, &b"c"[..]),
                (4, &b"d"[..])
            ]
        );
        let mut lines = Lines::numbered_from(b"x\r\ny", 7);
        assert_eq!(lines.next(), Some((7, &b"x"[..])));
        assert_eq!(lines.offset(), 3);
        assert_eq!(lines.next_number(), 8);
    }

    #[test]
    fn tokens_carry_their_line_numbers() {
        let mut tokens = Tokens::new(b"solid my part\n  facet normal\n\n 0 1\n");
        assert_eq!(tokens.next(), Some((1, &b"solid"[..])));
        tokens.skip_rest_of_line();
        let rest: Vec<_> = tokens.collect();
        assert_eq!(
            rest,
            vec![
                (2, &b"facet"[..]),
                (2, &b"normal"[..]),
                (4, &b"0"[..]),
                (4, &b"1"[..])
            ]
        );
    }

    #[test]
    fn quotes_are_short_and_printable() {
        assert_eq!(quote(b"abc"), "`abc`");
        assert_eq!(quote(b"a\x00\xffb"), "`a\\u{0}\u{fffd}b`");
        assert_eq!(quote(&[b'x'; 100]).chars().count(), QUOTE_MAX_CHARS + 3);
    }
}
