//! The bearer token (`--token-file`, `DPMP_API_TOKEN`).
//!
//! The token is kept only as its SHA-256 digest; a presented token is hashed
//! and compared with [`subtle::ConstantTimeEq`], so neither its content nor
//! its length leaks through timing. The token is never logged: [`Token`]'s
//! `Debug` prints `Token(<redacted>)`.

use sha2::{Digest, Sha256};
use subtle::ConstantTimeEq;

/// Environment variable read by `dpmp serve` for the token.
pub const TOKEN_ENV: &str = "DPMP_API_TOKEN";

/// A secret bearer token (stored hashed).
#[derive(Clone)]
pub struct Token {
    digest: [u8; 32],
}

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(<redacted>)")
    }
}

impl Token {
    /// A token from its text (surrounding whitespace, e.g. a file's final
    /// newline, is ignored). It must be 1..=4096 visible ASCII characters so
    /// that a client can send it in a header; `field` names the source in
    /// the error (`--token-file`, `DPMP_API_TOKEN`).
    pub fn new(field: &str, text: &str) -> crate::Result<Token> {
        let text = text.trim();
        if text.is_empty() || text.len() > 4096 {
            return Err(crate::Error::invalid(
                field,
                "the token must have 1..=4096 characters",
            ));
        }
        if !text.bytes().all(|b| b.is_ascii_graphic()) {
            return Err(crate::Error::invalid(
                field,
                "the token must be visible ASCII characters without spaces",
            ));
        }
        Ok(Token {
            digest: digest(text.as_bytes()),
        })
    }

    /// Whether `presented` is this token (constant time).
    pub fn matches(&self, presented: &[u8]) -> bool {
        self.digest.ct_eq(&digest(presented)).into()
    }
}

fn digest(bytes: &[u8]) -> [u8; 32] {
    Sha256::digest(bytes).into()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn token_matches_only_itself_and_is_redacted() {
        let t = Token::new("--token-file", "s3cret-token\n").unwrap();
        assert!(t.matches(b"s3cret-token"));
        assert!(!t.matches(b"s3cret-tokem"));
        assert!(!t.matches(b"s3cret-token "));
        assert!(!t.matches(b""));
        assert_eq!(format!("{t:?}"), "Token(<redacted>)");
    }

    #[test]
    fn bad_tokens_are_rejected_naming_the_source() {
        for bad in ["", "   ", "has space", "tab\tinside", "é"] {
            let e = Token::new("DPMP_API_TOKEN", bad).unwrap_err();
            assert_eq!(e.field(), Some("DPMP_API_TOKEN"), "{bad:?}");
        }
    }
}
