//! serde_json's messages in the reader's terms.

/// A serde_json error's message in the reader's terms: without its " at
/// line L column C" (for errors in a part of a document re-read on its own,
/// where that position means nothing) and without the Rust type names serde
/// puts in its "expected ..." (`struct WireRequest` is "an object").
pub fn message_of(e: &serde_json::Error) -> String {
    let text = e.to_string();
    let text = match text.rfind(" at line ") {
        Some(i) => &text[..i],
        None => &text,
    };
    without_type_names(text)
}

/// `text` with serde's `struct Name` / `enum Name` spelled as the JSON the
/// reader must send.
pub fn without_type_names(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    loop {
        let found = [
            ("struct ", "an object"),
            ("enum ", "one of its allowed strings"),
        ]
        .iter()
        .filter_map(|(word, words)| rest.find(word).map(|i| (i, *word, *words)))
        .min_by_key(|(i, ..)| *i);
        let Some((i, word, words)) = found else {
            out.push_str(rest);
            return out;
        };
        let after = &rest[i + word.len()..];
        let name_len = after
            .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
            .unwrap_or(after.len());
        let starts_a_type_name = after.starts_with(|c: char| c.is_ascii_uppercase());
        let word_starts = i == 0 || rest[..i].ends_with(' ');
        if starts_a_type_name && word_starts {
            let before = rest[..i]
                .trim_end_matches("untagged ")
                .trim_end_matches("tuple ");
            out.push_str(before);
            out.push_str(words);
            rest = without_arity(&after[name_len..]);
        } else {
            out.push_str(&rest[..i + word.len()]);
            rest = after;
        }
    }
}

/// `text` without a leading " with N element(s)" (serde's arity of a
/// struct read from an array, meaningless for an object).
fn without_arity(text: &str) -> &str {
    let Some(rest) = text.strip_prefix(" with ") else {
        return text;
    };
    let digits = rest
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(rest.len());
    if digits == 0 {
        return text;
    }
    let after = &rest[digits..];
    after
        .strip_prefix(" elements")
        .or_else(|| after.strip_prefix(" element"))
        .unwrap_or(text)
}
