"""tokenizer.json (HuggingFace format) from open_clip's BPE file, and the texts whose ids the
fixtures record."""

import gzip

from .constants import COLOUR_PROTOTYPES, COLOUR_SYNONYMS, CONTEXT_LENGTH, EOT_TOKEN, SOT_TOKEN


def bytes_to_unicode():
    """GPT-2/CLIP byte -> printable unicode character table (same as open_clip's)."""
    printable = list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), ord("ÿ") + 1))
    codes = printable[:]
    extra = 0
    for byte in range(256):
        if byte not in printable:
            printable.append(byte)
            codes.append(256 + extra)
            extra += 1
    return dict(zip(printable, [chr(c) for c in codes]))


def clip_vocab_and_merges(bpe_path):
    """Vocabulary (token -> id) and merge list exactly as open_clip's SimpleTokenizer builds them."""
    lines = gzip.open(bpe_path).read().decode("utf-8").split("\n")
    merges = [tuple(line.split()) for line in lines[1 : 49152 - 256 - 2 + 1]]
    byte_chars = list(bytes_to_unicode().values())
    tokens = byte_chars + [c + "</w>" for c in byte_chars] + ["".join(m) for m in merges]
    tokens += ["<|startoftext|>", "<|endoftext|>"]
    assert len(tokens) == EOT_TOKEN + 1
    return {t: i for i, t in enumerate(tokens)}, [" ".join(m) for m in merges]


# open_clip's pre-tokenizer regex (without its special-token alternatives, which HF handles as
# added tokens).
CLIP_PRETOKENIZE_REGEX = r"'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+"


def special_token(token_id, content):
    return {
        "id": token_id,
        "content": content,
        "single_word": False,
        "lstrip": False,
        "rstrip": False,
        "normalized": False,
        "special": True,
    }


def build_tokenizer_json(bpe_path):
    """CLIP's tokenizer as HF JSON: normalise (NFC, whitespace runs -> one space, strip, lower),
    split with CLIP's regex, byte-level map, BPE with '</w>' end-of-word suffix, wrap in
    <|startoftext|> ... <|endoftext|>, truncate to 77 (keeping end-of-text last) and pad with 0."""
    vocab, merges = clip_vocab_and_merges(bpe_path)
    return {
        "version": "1.0",
        "truncation": {"direction": "Right", "max_length": CONTEXT_LENGTH, "strategy": "LongestFirst", "stride": 0},
        "padding": {
            "strategy": {"Fixed": CONTEXT_LENGTH},
            "direction": "Right",
            "pad_to_multiple_of": None,
            "pad_id": 0,
            "pad_type_id": 0,
            "pad_token": "!",
        },
        "added_tokens": [special_token(SOT_TOKEN, "<|startoftext|>"), special_token(EOT_TOKEN, "<|endoftext|>")],
        "normalizer": {
            "type": "Sequence",
            "normalizers": [
                {"type": "NFC"},
                {"type": "Replace", "pattern": {"Regex": r"\s+"}, "content": " "},
                {"type": "Strip", "strip_left": True, "strip_right": True},
                {"type": "Lowercase"},
            ],
        },
        "pre_tokenizer": {
            "type": "Sequence",
            "pretokenizers": [
                {"type": "Split", "pattern": {"Regex": CLIP_PRETOKENIZE_REGEX}, "behavior": "Removed", "invert": True},
                {"type": "ByteLevel", "add_prefix_space": False, "trim_offsets": True, "use_regex": False},
            ],
        },
        "post_processor": {
            "type": "TemplateProcessing",
            "single": [
                {"SpecialToken": {"id": "<|startoftext|>", "type_id": 0}},
                {"Sequence": {"id": "A", "type_id": 0}},
                {"SpecialToken": {"id": "<|endoftext|>", "type_id": 0}},
            ],
            "pair": [
                {"SpecialToken": {"id": "<|startoftext|>", "type_id": 0}},
                {"Sequence": {"id": "A", "type_id": 0}},
                {"SpecialToken": {"id": "<|endoftext|>", "type_id": 0}},
                {"Sequence": {"id": "B", "type_id": 1}},
                {"SpecialToken": {"id": "<|endoftext|>", "type_id": 1}},
            ],
            "special_tokens": {
                "<|startoftext|>": {"id": "<|startoftext|>", "ids": [SOT_TOKEN], "tokens": ["<|startoftext|>"]},
                "<|endoftext|>": {"id": "<|endoftext|>", "ids": [EOT_TOKEN], "tokens": ["<|endoftext|>"]},
            },
        },
        "decoder": {"type": "BPEDecoder", "suffix": "</w>"},
        "model": {
            "type": "BPE",
            "dropout": None,
            "unk_token": "<|endoftext|>",
            "continuing_subword_prefix": None,
            "end_of_word_suffix": "</w>",
            "fuse_unk": False,
            "byte_fallback": False,
            "ignore_merges": False,
            "vocab": vocab,
            "merges": merges,
        },
    }


# Texts whose open_clip ids the fixture records. The long one exceeds 77 tokens.
TOKENIZER_TEXTS = [
    "",
    "a red mug",
    "A photo of a RED Mug.",
    "red",
    "the chair",
    "  lots   of\twhitespace \n\n here  ",
    "café crème brûlée, naïve façade",
    "Ünïcödé ÀÉÎÕÜ ß",
    "東京タワー と 猫",
    "한국어 텍스트",
    "🙂 happy face 🎉🎉",
    "👩‍👩‍👧 family emoji with ZWJ",
    "Hello, world! (parentheses) [brackets] {braces} <angle>",
    "it's they're we've I'm you'll he'd",
    "punctuation!!! ??? ... --- ;;; :::",
    "numbers 123 4567 3.14159 1,000,000 2024-05-17",
    "MiXeD CaSe WoRdS",
    "a_snake_case_identifier and CamelCaseIdentifier",
    "email@example.com http://example.org/path?q=1",
    "tab\tseparated\tvalues",
    "the quick brown fox jumps over the lazy dog " * 12,
    "word " * 80,
]
# Texts where open_clip's extra cleaning (ftfy.fix_text, html.unescape) changes the text before
# tokenising, so an HF tokenizer.json alone cannot reproduce the ids; recorded separately (the Rust
# ClipTokenizer cleans first and does; scripts/make_tokenizer_table.py writes many more).
TOKENIZER_CLEANING_TEXTS = [
    "fish &amp; chips",
    "&lt;b&gt;bold&lt;/b&gt;",
    "don’t “quote” me",
    "ﬁne ligature",
    "ＦＵＬＬＷＩＤＴＨ text",
]


def tokenizer_cases(texts):
    import open_clip

    tokenizer = open_clip.get_tokenizer("ViT-B-32")
    ids = tokenizer(texts).tolist()
    return [{"text": text, "ids": row} for text, row in zip(texts, ids)]


def hf_tokenizer_ids(tokenizer_path, texts):
    from tokenizers import Tokenizer

    tokenizer = Tokenizer.from_file(tokenizer_path)
    return [encoding.ids for encoding in tokenizer.encode_batch(texts)]


def colour_token_ids():
    """{CLIP BPE id: colour name} for every colour word and synonym (each a single token)."""
    import open_clip

    tokenizer = open_clip.get_tokenizer("ViT-B-32")
    words = {name: name for name in COLOUR_PROTOTYPES}
    words.update(COLOUR_SYNONYMS)
    table = {}
    for word, colour in words.items():
        ids = tokenizer.encode(word)
        assert len(ids) == 1, f"colour word {word!r} is not a single CLIP token: {ids}"
        table[ids[0]] = colour
    return table
