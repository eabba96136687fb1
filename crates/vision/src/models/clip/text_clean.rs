//! open_clip's text clean-up, done before BPE so that prompts get open_clip's ids.
//!
//! open_clip (3.x, `SimpleTokenizer` with `clean="lower"`) runs `ftfy.fix_text` (ftfy 6, default
//! settings), then `html.unescape` twice, then splits on whitespace and joins with one space, then
//! lower-cases. The HF `tokenizer.json` normalizer (NFC, `\s+` to a space, lower case) does only the
//! last two, so `don’t`, `fish &amp; chips`, `ＦＵＬＬＷＩＤＴＨ` or `ﬁne` came out differently.
//!
//! Reproduced from ftfy's `fix_text`, in its order and per line as it does:
//! HTML entity decoding (ftfy's variant: semicolon-terminated names, numeric references, and
//! upper-cased names such as `&EACUTE;`; skipped from the first line containing a literal `<`
//! on), C1 controls read as Windows-1252, Latin ligatures and digraphs expanded, full-width and
//! half-width forms folded, curly quotes straightened, line breaks unified, terminal escapes and
//! invisible control characters removed, NFC; all repeated until nothing changes, as ftfy does.
//! Python's `html.unescape` is reproduced as Python implements it (named references without a
//! semicolon, numeric references with its replacement table and the code points it drops).
//! Whitespace and lower case follow Python's `str.split()` and `str.lower()`.
//!
//! Not reproduced: ftfy's mojibake repair (`fix_encoding`: re-decoding text such as `cafÃ©`, and
//! its helpers `restore_byte_a0`, `replace_lossy_sequences`, `decode_inconsistent_utf8`). It is a
//! heuristic that scores whole strings and rarely fires on typed prompts; text it would change
//! keeps its mojibake here. `fix_surrogates` has nothing to do: a Rust `str` holds no surrogates.
//! Unicode tables are Rust's and the crates', which may be newer than Python's; only characters
//! assigned since then can differ.

use std::collections::HashMap;
use std::sync::LazyLock;

use regex::Regex;
use unicode_normalization::UnicodeNormalization;

/// The text open_clip hands to BPE for `text`.
pub fn clean_text(text: &str) -> String {
    let fixed = fix_text(text);
    let unescaped = html_unescape(&html_unescape(&fixed));
    // `basic_clean`'s `strip()` and `whitespace_clean`'s `" ".join(text.split())` together.
    let words: Vec<&str> = unescaped
        .split(is_python_space)
        .filter(|word| !word.is_empty())
        .collect();
    words.join(" ").to_lowercase()
}

/// `str.isspace()`: Unicode White_Space plus U+001C..U+001F, which Python counts as separators.
fn is_python_space(c: char) -> bool {
    c.is_whitespace() || ('\u{1c}'..='\u{1f}').contains(&c)
}

/// ftfy's `max_decode_length`: it fixes at most this many code points at once.
const MAX_SEGMENT_CHARS: usize = 1_000_000;

/// `ftfy.fix_text` without `fix_encoding`.
fn fix_text(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    // ftfy turns entity decoding off for good at the first segment holding a '<' (that text is
    // probably HTML, whose entities are meant), so later lines keep their entities too.
    let mut unescape = true;
    for segment in segments(text) {
        if unescape && segment.contains('<') {
            unescape = false;
        }
        out.push_str(&fix_segment(segment, unescape));
    }
    out
}

/// Lines including their '\n', cut further every `MAX_SEGMENT_CHARS` code points.
fn segments(text: &str) -> Vec<&str> {
    let mut segments = Vec::new();
    let mut start = 0;
    let mut chars = 0;
    for (index, c) in text.char_indices() {
        chars += 1;
        if c == '\n' || chars == MAX_SEGMENT_CHARS {
            let end = index + c.len_utf8();
            segments.push(&text[start..end]);
            start = end;
            chars = 0;
        }
    }
    if start < text.len() {
        segments.push(&text[start..]);
    }
    segments
}

/// `ftfy.fix_and_explain` on one segment: every fixer in ftfy's order, until a pass changes
/// nothing (decoding `&amp;amp;` yields `&amp;`, which the next pass decodes).
fn fix_segment(segment: &str, unescape: bool) -> String {
    let mut text = segment.to_string();
    loop {
        let mut fixed = if unescape {
            ftfy_unescape_html(&text)
        } else {
            text.clone()
        };
        fixed = fixed.chars().map(fix_c1_control).collect();
        fixed = fix_latin_ligatures(&fixed);
        fixed = fix_character_width(&fixed);
        fixed = fixed.chars().map(uncurl_quote).collect();
        fixed = fix_line_breaks(&fixed);
        fixed = TERMINAL_ESCAPE.replace_all(&fixed, "").into_owned();
        fixed.retain(|c| !is_removed_control(c));
        fixed = fixed.nfc().collect();
        if fixed == text {
            return fixed;
        }
        text = fixed;
    }
}

/// ftfy's `unescape_html`: only `&name;` or `&#...;` with 1 to 24 ASCII letters or digits;
/// names come from the HTML5 table (plus ftfy's upper-cased ones), numeric references from
/// `html.unescape` unless it leaves a ';' (not a complete reference, e.g. `&#65abc;`).
fn ftfy_unescape_html(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(amp) = rest.find('&') {
        out.push_str(&rest[..amp]);
        rest = &rest[amp..];
        let Some(len) = ftfy_entity_len(rest) else {
            out.push('&');
            rest = &rest[1..];
            continue;
        };
        let entity = &rest[..len];
        if let Some(expansion) = FTFY_ENTITIES.get(entity) {
            out.push_str(expansion);
        } else if entity.starts_with("&#") {
            let decoded = html_unescape(entity);
            out.push_str(if decoded.contains(';') {
                entity
            } else {
                &decoded
            });
        } else {
            out.push_str(entity);
        }
        rest = &rest[len..];
    }
    out.push_str(rest);
    out
}

/// Length in bytes of ftfy's `&#?[0-9A-Za-z]{1,24};` at the start of `text`.
fn ftfy_entity_len(text: &str) -> Option<usize> {
    let bytes = text.as_bytes();
    let start = if bytes.get(1) == Some(&b'#') { 2 } else { 1 };
    let run = bytes[start..]
        .iter()
        .take_while(|b| b.is_ascii_alphanumeric())
        .count();
    ((1..=24).contains(&run) && bytes.get(start + run) == Some(&b';')).then_some(start + run + 1)
}

/// ftfy's `HTML_ENTITIES`: the HTML5 names ending in ';', and for each all-lower-case name its
/// upper-cased form (expanding to the upper-cased character) unless that already means something.
static FTFY_ENTITIES: LazyLock<HashMap<String, String>> = LazyLock::new(|| {
    let mut entities = HashMap::new();
    for (name, expansion) in html5_entities() {
        if !name.ends_with(';') {
            continue;
        }
        entities.insert(name.to_string(), expansion.to_string());
        if name == name.to_ascii_lowercase() {
            let upper = name.to_ascii_uppercase();
            if html_unescape(&upper) == upper {
                entities.insert(upper, expansion.to_uppercase());
            }
        }
    }
    entities
});

/// The WHATWG table (the same 2231 entries as Python's `html.entities.html5`), `&` included.
fn html5_entities() -> impl Iterator<Item = (&'static str, &'static str)> {
    htmlize::ENTITIES.entries().filter_map(|(name, expansion)| {
        Some((
            std::str::from_utf8(name).ok()?,
            std::str::from_utf8(expansion).ok()?,
        ))
    })
}

fn html5_entity(name: &str) -> Option<&'static str> {
    let expansion = htmlize::ENTITIES.get(name.as_bytes())?;
    std::str::from_utf8(expansion).ok()
}

/// Python's `html.unescape`. It differs from the WHATWG algorithm (and `htmlize::unescape`) in
/// which numeric references it drops and in taking the longest table prefix of any run of up to
/// 32 characters, so it is written out here rather than borrowed.
fn html_unescape(text: &str) -> String {
    if !text.contains('&') {
        return text.to_string();
    }
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(amp) = rest.find('&') {
        out.push_str(&rest[..amp]);
        rest = &rest[amp..];
        let consumed = match rest.as_bytes().get(1) {
            Some(b'#') => unescape_numeric(rest, &mut out),
            Some(_) => unescape_named(rest, &mut out),
            None => None,
        };
        match consumed {
            Some(len) => rest = &rest[len..],
            None => {
                out.push('&');
                rest = &rest[1..];
            }
        }
    }
    out.push_str(rest);
    out
}

/// `&#[0-9]+;?` or `&#[xX][0-9a-fA-F]+;?` at the start of `text`: appends the expansion and
/// returns the length matched.
fn unescape_numeric(text: &str, out: &mut String) -> Option<usize> {
    let bytes = text.as_bytes();
    let (radix, digits_start) = match bytes.get(2) {
        Some(b'x' | b'X') => (16, 3),
        _ => (10, 2),
    };
    let digits = bytes[digits_start..]
        .iter()
        .take_while(|b| char::from(**b).is_digit(radix))
        .count();
    if digits == 0 {
        return None;
    }
    // Anything past U+10FFFF becomes U+FFFD, so saturating there loses nothing.
    let value = bytes[digits_start..digits_start + digits]
        .iter()
        .fold(0u32, |value, b| {
            let digit = char::from(*b).to_digit(radix).unwrap_or(0);
            value
                .saturating_mul(radix)
                .saturating_add(digit)
                .min(0x11_0000)
        });
    let mut len = digits_start + digits;
    if bytes.get(len) == Some(&b';') {
        len += 1;
    }
    if let Some(replacement) = python_charref_replacement(value) {
        out.push(replacement);
    } else if (0xD800..=0xDFFF).contains(&value) || value > 0x10_FFFF {
        out.push('\u{fffd}');
    } else if !is_python_invalid_codepoint(value) {
        out.extend(char::from_u32(value));
    }
    Some(len)
}

/// Python's `_invalid_charrefs`: NUL, CR and the C1 range read as Windows-1252.
fn python_charref_replacement(value: u32) -> Option<char> {
    match value {
        0x00 => Some('\u{fffd}'),
        0x0d => Some('\r'),
        0x80..=0x9f => Some(windows_1252_c1(value)),
        _ => None,
    }
}

/// Python's `_invalid_codepoints`, which `html.unescape` drops.
fn is_python_invalid_codepoint(value: u32) -> bool {
    matches!(value, 0x01..=0x08 | 0x0b | 0x0e..=0x1f | 0x7f..=0x9f | 0xfdd0..=0xfdef)
        || value & 0xfffe == 0xfffe
}

/// `&name` at the start of `text`, Python's way: the run of up to 32 characters other than
/// `\t \n \f space < & # ;`, an optional ';', then the whole run if it is a name, else its longest
/// prefix (at least 2 characters) that is one, followed by the rest of the run unchanged.
fn unescape_named(text: &str, out: &mut String) -> Option<usize> {
    let after_amp = &text[1..];
    let run_len: usize = after_amp
        .chars()
        .take_while(|c| !matches!(c, '\t' | '\n' | '\x0c' | ' ' | '<' | '&' | '#' | ';'))
        .take(32)
        .map(char::len_utf8)
        .sum();
    if run_len == 0 {
        return None;
    }
    let mut name_len = run_len;
    if after_amp.as_bytes().get(run_len) == Some(&b';') {
        name_len += 1;
    }
    let name = &after_amp[..name_len];
    let matched = 1 + name_len;
    if let Some(expansion) = html5_entity(&text[..matched]) {
        out.push_str(expansion);
        return Some(matched);
    }
    let boundaries: Vec<usize> = name
        .char_indices()
        .map(|(index, _)| index)
        .skip(2)
        .collect();
    for &prefix_len in boundaries.iter().rev() {
        if let Some(expansion) = html5_entity(&text[..1 + prefix_len]) {
            out.push_str(expansion);
            out.push_str(&name[prefix_len..]);
            return Some(matched);
        }
    }
    out.push_str(&text[..matched]);
    Some(matched)
}

/// Windows-1252's character for a C1 byte; the five bytes it leaves undefined stay as they are
/// (ftfy's "sloppy" codec).
fn windows_1252_c1(value: u32) -> char {
    match value {
        0x80 => '\u{20ac}',
        0x82 => '\u{201a}',
        0x83 => '\u{0192}',
        0x84 => '\u{201e}',
        0x85 => '\u{2026}',
        0x86 => '\u{2020}',
        0x87 => '\u{2021}',
        0x88 => '\u{02c6}',
        0x89 => '\u{2030}',
        0x8a => '\u{0160}',
        0x8b => '\u{2039}',
        0x8c => '\u{0152}',
        0x8e => '\u{017d}',
        0x91 => '\u{2018}',
        0x92 => '\u{2019}',
        0x93 => '\u{201c}',
        0x94 => '\u{201d}',
        0x95 => '\u{2022}',
        0x96 => '\u{2013}',
        0x97 => '\u{2014}',
        0x98 => '\u{02dc}',
        0x99 => '\u{2122}',
        0x9a => '\u{0161}',
        0x9b => '\u{203a}',
        0x9c => '\u{0153}',
        0x9e => '\u{017e}',
        0x9f => '\u{0178}',
        _ => char::from_u32(value).unwrap_or('\u{fffd}'),
    }
}

/// ftfy's `fix_c1_controls`: a C1 control in otherwise decoded text is a Windows-1252 byte that
/// was read as Latin-1.
fn fix_c1_control(c: char) -> char {
    if ('\u{80}'..='\u{9f}').contains(&c) {
        windows_1252_c1(u32::from(c))
    } else {
        c
    }
}

/// ftfy's `LIGATURES`: Latin typographic ligatures and the legacy digraphs; other scripts'
/// ligatures and `æ`/`œ` are left alone.
fn fix_latin_ligatures(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        let expansion = match c {
            'Ĳ' => "IJ",
            'ĳ' => "ij",
            'ŉ' => "\u{02bc}n",
            'Ǳ' => "DZ",
            'ǲ' => "Dz",
            'ǳ' => "dz",
            'Ǆ' => "D\u{017d}",
            'ǅ' => "D\u{017e}",
            'ǆ' => "d\u{017e}",
            'Ǉ' => "LJ",
            'ǈ' => "Lj",
            'ǉ' => "lj",
            'Ǌ' => "NJ",
            'ǋ' => "Nj",
            'ǌ' => "nj",
            'ﬀ' => "ff",
            'ﬁ' => "fi",
            'ﬂ' => "fl",
            'ﬃ' => "ffi",
            'ﬄ' => "ffl",
            'ﬅ' => "\u{017f}t",
            'ﬆ' => "st",
            _ => {
                out.push(c);
                continue;
            }
        };
        out.push_str(expansion);
    }
    out
}

/// ftfy's `fix_character_width`: the ideographic space becomes a space, and every character of
/// the Halfwidth and Fullwidth Forms block (U+FF01..U+FFEF) its NFKC form.
fn fix_character_width(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '\u{3000}' => out.push(' '),
            '\u{ff01}'..='\u{ffef}' => out.extend(std::iter::once(c).nfkc()),
            _ => out.push(c),
        }
    }
    out
}

/// ftfy's `uncurl_quotes`.
fn uncurl_quote(c: char) -> char {
    match c {
        '\u{02bc}' | '\u{2018}'..='\u{201b}' => '\'',
        '\u{201c}'..='\u{201f}' => '"',
        _ => c,
    }
}

/// ftfy's `fix_line_breaks`, in its order (CRLF before a lone CR).
fn fix_line_breaks(text: &str) -> String {
    text.replace("\r\n", "\n")
        .replace(['\r', '\u{2028}', '\u{2029}', '\u{85}'], "\n")
}

/// ftfy's `ANSI_RE`; like Python's `\d`, the regex crate's `\d` takes any Unicode decimal digit.
static TERMINAL_ESCAPE: LazyLock<Regex> = LazyLock::new(|| {
    Regex::new(r"\x1b\[[\d;]*[a-zA-Z]").expect("terminal escape pattern is valid")
});

/// ftfy's `remove_control_chars`: controls with no visible effect. Whitespace controls, C1
/// controls, joiners and direction marks, and tag characters (emoji flags) are kept.
fn is_removed_control(c: char) -> bool {
    matches!(
        c,
        '\u{00}'..='\u{08}'
            | '\u{0b}'
            | '\u{0e}'..='\u{1f}'
            | '\u{7f}'
            | '\u{206a}'..='\u{206f}'
            | '\u{feff}'
            | '\u{fff9}'..='\u{fffc}'
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    // Expected outputs are open_clip 3.3.0's `_clean_lower` (ftfy 6.3.1, Python 3.11).
    #[test]
    fn cleans_like_open_clip() {
        for (text, expected) in [
            ("don’t “quote” me", "don't \"quote\" me"),
            ("fish &amp; chips &copy 2024", "fish & chips © 2024"),
            ("&amp;amp; &amp;lt;tag&amp;gt;", "& <tag>"),
            ("P&EACUTE;REZ &nTILDE;", "pérez &ntilde;"),
            (
                "x &EACUTE; y\nthe < line &EACUTE;\n&EACUTE; after",
                "x é y the < line &eacute; &eacute; after",
            ),
            (
                "a&#0;b &#x9F; c&#1;d &#xD800; &#65abc; &#59;",
                "a\u{fffd}b ÿ cd \u{fffd} aabc; ;",
            ),
            (
                "ＦＵＬＬＷＩＤＴＨ\u{3000}ｔｅｘｔ １２３！",
                "fullwidth text 123!",
            ),
            ("ｶﾞｷﾞ", "ガギ"),
            ("ﬁne ﬂour Ĳssel ǅ ŉ", "fine flour ijssel dž 'n"),
            ("cafe\u{301} A\u{30a}", "café å"),
            (
                "\u{93}smart\u{94} \u{85} \u{80}100 a\u{81}b",
                "\"smart\" … €100 a\u{81}b",
            ),
            ("\x1b[1;32mbold\x1b[m text", "bold text"),
            (
                "one\r\ntwo\u{2028}three\tfour\u{a0}five\x0bsix",
                "one two three four fivesix",
            ),
            (
                "bom\u{feff}in nul\0 zero\u{200b}width",
                "bomin nul zero\u{200b}width",
            ),
            ("ÉCOLE GROẞE İ ΟΔΥΣΣΕΥΣ", "école große i\u{307} οδυσσευς"),
            ("  \t\n ", ""),
        ] {
            assert_eq!(clean_text(text), expected, "{text:?}");
        }
    }

    #[test]
    fn python_html_unescape_edge_cases() {
        for (text, expected) in [
            ("&amp &ampfoo &notit; &lt3", "& &foo ¬it; <3"),
            ("&#X41;&#x62;&#0065; &#128;", "AbA €"),
            ("&#x110000; &#99999999999999999999;", "\u{fffd} \u{fffd}"),
            ("&#x81; &#x7f; &#xfdd0; &#xffff; &#13;", "\u{81}    \r"),
            ("& &# &#x &unknown; &;", "& &# &#x &unknown; &;"),
        ] {
            assert_eq!(html_unescape(text), expected, "{text:?}");
        }
    }

    #[test]
    fn ftfy_decodes_only_terminated_references() {
        assert_eq!(
            ftfy_unescape_html("&amp &amp; &AMP; &NTILDE; &#39; &#59; &lt3"),
            "&amp & & Ñ ' &#59; &lt3"
        );
    }

    #[test]
    fn segments_keep_line_ends() {
        assert_eq!(segments("a\nb\n\nc"), vec!["a\n", "b\n", "\n", "c"]);
        assert!(segments("").is_empty());
    }
}
