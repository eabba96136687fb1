#!/usr/bin/env python3
"""Write tests/fixtures/clip/tokenizer_open_clip_table.json: open_clip's ids for texts that its
clean-up (ftfy.fix_text, html.unescape twice, whitespace, lower case) changes.

Usage (from the repository root, in a venv with open_clip_torch and ftfy):

    python scripts/make_tokenizer_table.py

The Rust ClipTokenizer (src/models/clip/text_clean.rs + tokenizer.rs) must reproduce every case
exactly (tests/models/clip.rs). ftfy's mojibake repair (fix_encoding) is heuristic and not
reproduced in Rust, so the script refuses texts whose result depends on it.
"""

import json
import os
import sys

import ftfy
import open_clip
from open_clip.tokenizer import _clean_lower

REPO_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT_PATH = os.path.join(REPO_ROOT, "tests", "fixtures", "clip", "tokenizer_open_clip_table.json")

TEXTS = [
    # quotes and apostrophes: straight, curly (U+2018..U+201F), modifier letter apostrophe
    "don't say \"cheese\"",
    "don\u2019t \u201cquote\u201d me",
    "\u2018single\u2019 \u201adouble low\u201b \u201fhigh\u201e it\u02bcs",
    # HTML entities: named, numeric, hex, without semicolon, double-escaped
    "fish &amp; chips &lt;3 &quot;fresh&quot; &copy; 2024 caf&eacute; &hellip;&mdash;&nbsp;end",
    "&#65;&#66;&#67; &#8364;5 it&#x2019;s &#X41;&#x62; &#0065;",
    "fish &amp chips &copy 2024 &notit; &ampfoo &lt3 &unknown; & alone",
    "&amp;amp; &amp;lt;tag&amp;gt; &amp;amp;amp;amp; &amp;#39;",
    # ftfy also decodes upper-cased entities; html.unescape does not
    "P&EACUTE;REZ BUNDESSTRA&SZLIG;E &NTILDE; &nTILDE; &FRAC12;",
    # numeric references HTML5 replaces or drops
    "a&#0;b &#128;100 &#x9F; &#x81; c&#1;d &#xD800; &#x110000; &#65abc; &#59; &#x1F600;",
    # a literal '<': ftfy leaves entities alone, open_clip's two html.unescape calls still decode
    "a < b &amp; c &gt; d &amp;amp;",
    "x<y &EACUTE; e&#769; &#x2019;s",
    # ftfy decides per line: lines after the first one with '<' are not unescaped by ftfy either
    "x &EACUTE; y\nthe < line &EACUTE;\n&EACUTE; after",
    "text with <b>html</b> &amp; &lt;tags&gt;",
    # full width letters, digits, punctuation, ideographic space, an entity in full width
    "\uff26\uff35\uff2c\uff2c\uff37\uff29\uff24\uff34\uff28\u3000\uff54\uff45\uff58\uff54 \uff11\uff12\uff13\uff01\uff1f",
    "\uff06\uff41\uff4d\uff50\uff1b \uffe5100 \uffe0",
    # half width katakana (voiced marks compose after width folding) and half width Hangul
    "\uff8a\uff9d\uff76\uff78 \uff76\uff9e\uff77\uff9e \uffa1\uffa4",
    # ligatures and digraphs
    "\ufb01ne \ufb02our \ufb00 \ufb03 \ufb04 \ufb05 \ufb06 \u0132ssel \u0133s",
    "\u01c4 \u01c5 \u01c6 \u01c7 \u01c8 \u01c9 \u01ca \u01cb \u01cc \u01f1 \u01f2 \u01f3 \u0149",
    # accents, precomposed and decomposed (combining marks compose under NFC)
    "\u00c9lan \u00c7a \u0152uvre cr\u00e8me br\u00fbl\u00e9e",
    "cafe\u0301 cre\u0300me n\u0303 o\u0308 A\u030a",
    "\u1100\u1161\u11a8 decomposed hangul",
    # emoji: skin tones, ZWJ sequences, flags, variation selectors, keycaps
    "\U0001f44d\U0001f3fd \U0001f469\U0001f3fe\u200d\U0001f4bb \U0001f1eb\U0001f1f7 \U0001f1ef\U0001f1f5",
    "\U0001f3f3\ufe0f\u200d\U0001f308 \u2764\ufe0f 1\ufe0f\u20e3 \U0001f468\u200d\U0001f469\u200d\U0001f467\u200d\U0001f466",
    # CJK and Hangul
    "\u5317\u4eac \u4e0a\u6d77 \u6771\u4eac\u30bf\u30ef\u30fc \u3068 \u732b",
    "\uc548\ub155\ud558\uc138\uc694 \uc138\uacc4",
    # C1 controls (Windows-1252 meanings; 0x81, 0x8d, 0x8f, 0x90 and 0x9d have none)
    "\x93smart\x94 \x91quotes\x92 \x85 \x80100 \x96 a\x81b\x9dc",
    # terminal escapes
    "\x1b[31mred\x1b[0m text \x1b[1;32mbold green\x1b[m \x1b[2K",
    # line breaks, tabs, non-breaking and other spaces
    "line one\nline two\r\nthree\rfour\u2028five\u2029six\ttab\u00a0nbsp\u202fnarrow\u3000ideo\x0cff\x0bvt",
    # control characters ftfy removes, and some it keeps
    "zero\u200bwidth soft\u00adhyphen bom\ufeffin nul\x00bell\x07 del\x7f \u206aarabic \ufffcobj \ufff9ann",
    # case: non-ASCII upper case, sharp s, Turkish dotted I, Greek final sigma, title-case digraph
    "\u00c9COLE \u00c9T\u00c9 \u00c0 PARIS",
    "STRASSE stra\u00dfe \u1e9e GRO\u1e9eE",
    "\u0130stanbul ISTANBUL \u0131i \u0130",
    "\u039f\u0394\u03a5\u03a3\u03a3\u0395\u03a5\u03a3 \u03a3 \u03a3\u039f\u03a6\u0399\u0391",
    "MiXeD \u00c7aSe \u00c0\u00c9\u00ce \u00d1O\u00d1O",
    # longer than 77 tokens after clean-up
    "a \uff26\uff35\uff2c\uff2c photo of &amp; \ufb01sh, \u201cdon\u2019t\u201d " * 12,
    # typed special tokens: open_clip's own become its ids where its scan meets them (not glued
    # to punctuation); the HF spellings are plain text, never an early end
    "a <start_of_text> red mug",
    "the <|endoftext|> mug <|startoftext|>red",
    "<END_OF_TEXT> x<<start_of_text> red<start_of_text>mug",
    # empty and whitespace only
    "",
    "   \t\n  ",
    "\u3000\u00a0\u2028 \r\n",
]


def main():
    depends_on_mojibake_repair = [
        text for text in TEXTS if ftfy.fix_text(text) != ftfy.fix_text(text, fix_encoding=False)
    ]
    if depends_on_mojibake_repair:
        sys.exit(f"ftfy's fix_encoding changes these, which Rust does not reproduce: {depends_on_mojibake_repair}")
    tokenizer = open_clip.get_tokenizer("ViT-B-32")
    ids = tokenizer(TEXTS).tolist()
    # one case per line keeps the fixture readable and its diffs small
    lines = [json.dumps({"text": text, "ids": row}, ensure_ascii=False) for text, row in zip(TEXTS, ids)]
    with open(OUT_PATH, "w", encoding="utf-8") as f:
        f.write("[\n" + ",\n".join(lines) + "\n]\n")
    print(f"{len(TEXTS)} cases -> {os.path.relpath(OUT_PATH, REPO_ROOT)}")
    print(f"open_clip_torch {open_clip.__version__}, ftfy {ftfy.__version__}, Python {sys.version.split()[0]}")
    if "--show" in sys.argv:
        for text in TEXTS:
            print(f"{text!r} -> {_clean_lower(text)!r}")


if __name__ == "__main__":
    main()
