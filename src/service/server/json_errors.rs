//! hyper's own error answers in the service's JSON error format.
//!
//! When a request cannot be parsed as HTTP/1.1 (a bad request line or
//! header, headers over the size limit, a URI too long), hyper answers
//! before any handler runs, with an empty body: `400`, `431` or `414` and
//! `content-length: 0`. hyper has no hook for that answer, so the
//! connection's writer ([`JsonErrors`]) recognises exactly that head (one
//! of those statuses, a zero content length, nothing after the head; the
//! service's own error answers always carry a body) and writes in its
//! place the same status with `{"error": {"code", "message", "field"}}`
//! and `connection: close`. hyper closes the connection after it either
//! way. The connection must write with `writev(false)`, so that a head
//! arrives in one buffer.
//!
//! Two ends hyper gives no answer at all, the accept loop answers once
//! hyper hands the connection back ([`JsonErrors::last_word`]):
//!
//! - **an HTTP/2 connection preface** (`PRI * HTTP/2.0`, a client speaking
//!   HTTP/2 with prior knowledge): the HTTP/2 answer for "use HTTP/1.1", a
//!   `SETTINGS` frame and a `GOAWAY` with `HTTP_1_1_REQUIRED` (RFC 9113
//!   §7), whose debug data is the JSON error;
//! - **a request head cut by the header timeout** (some bytes of a request
//!   arrived, not all its headers): 408 `header_timeout` in JSON. A
//!   connection idle between requests (no byte of a new one) is closed
//!   without a word, as RFC 9112 §9.6 allows: an answer there could be
//!   taken for the answer to a request the client is just sending.

use std::io;
use std::pin::Pin;
use std::task::{ready, Context, Poll};
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};

/// A connection whose writes of hyper's automatic error answers are
/// replaced by JSON ones (see the module docs).
#[derive(Debug)]
pub struct JsonErrors<T> {
    inner: T,
    /// A replacement being written: its bytes, how many are out, and the
    /// length of the head it stands for (what the caller is told).
    pending: Option<(Vec<u8>, usize, usize)>,
    /// The first bytes the client sent (up to the HTTP/2 preface's start).
    first_bytes: Vec<u8>,
    /// Bytes of a request arrived since the last answer was written.
    request_begun: bool,
}

/// The start of the HTTP/2 connection preface.
const H2_PREFACE: &[u8] = b"PRI * HTTP/2.0";

/// How a connection ended, for [`JsonErrors::last_word`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum End {
    /// hyper's header read timeout fired.
    HeaderTimeout,
    /// Any other end.
    Other,
}

impl<T> JsonErrors<T> {
    /// Wrap a connection.
    pub fn new(inner: T) -> Self {
        JsonErrors {
            inner,
            pending: None,
            first_bytes: Vec::new(),
            request_begun: false,
        }
    }

    /// The wrapped connection.
    pub fn into_inner(self) -> T {
        self.inner
    }

    /// What to send before closing a connection that ended as `end`, when
    /// hyper sent nothing (see the module docs); `header_timeout` goes in
    /// the message.
    pub fn last_word(&self, end: End, header_timeout: std::time::Duration) -> Option<Vec<u8>> {
        if self.first_bytes.starts_with(H2_PREFACE) {
            return Some(http2_goaway());
        }
        if end == End::HeaderTimeout && self.request_begun {
            let body = error_body(
                "header_timeout",
                &format!(
                    "the request headers did not arrive within {} ms",
                    header_timeout.as_millis()
                ),
            );
            return Some(http1_answer("408 Request Timeout", &body));
        }
        None
    }

    /// Note bytes read from the client.
    fn saw(&mut self, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        self.request_begun = true;
        let room = H2_PREFACE.len().saturating_sub(self.first_bytes.len());
        self.first_bytes
            .extend_from_slice(&bytes[..room.min(bytes.len())]);
    }
}

/// `{"error": {"code", "message", "field": null}}`.
pub(super) fn error_body(code: &str, message: &str) -> String {
    serde_json::json!({"error": {"code": code, "message": message, "field": null}}).to_string()
}

/// An HTTP/1.1 answer with a JSON body that closes the connection.
fn http1_answer(status_line: &str, body: &str) -> Vec<u8> {
    format!(
        "HTTP/1.1 {status_line}\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
        body.len()
    )
    .into_bytes()
}

/// An empty HTTP/2 `SETTINGS` frame and a `GOAWAY` (last stream 0, error
/// `HTTP_1_1_REQUIRED` = 0xd) carrying the JSON error as debug data.
fn http2_goaway() -> Vec<u8> {
    let body = error_body(
        "http2_not_supported",
        "this server speaks HTTP/1.1 only: send the request over HTTP/1.1",
    );
    let frame = |kind: u8, payload: &[u8]| {
        let len = payload.len() as u32;
        let mut f = vec![(len >> 16) as u8, (len >> 8) as u8, len as u8, kind, 0];
        f.extend_from_slice(&0u32.to_be_bytes());
        f.extend_from_slice(payload);
        f
    };
    let mut goaway = Vec::with_capacity(8 + body.len());
    goaway.extend_from_slice(&0u32.to_be_bytes());
    goaway.extend_from_slice(&0xdu32.to_be_bytes());
    goaway.extend_from_slice(body.as_bytes());
    let mut out = frame(0x4, &[]);
    out.extend(frame(0x7, &goaway));
    out
}

/// The statuses hyper answers by itself, with the JSON code and message.
const AUTOMATIC: [(&str, &str, &str); 3] = [
    (
        "400 Bad Request",
        "malformed_request",
        "the request line or a header is not valid HTTP/1.1",
    ),
    (
        "431 Request Header Fields Too Large",
        "headers_too_large",
        "the request headers exceed the server's limit",
    ),
    (
        "414 URI Too Long",
        "uri_too_long",
        "the request URI exceeds the server's limit",
    ),
];

/// The JSON answer for `head` when it is one of hyper's automatic error
/// heads, else `None`.
pub fn replacement(head: &[u8]) -> Option<Vec<u8>> {
    let text = std::str::from_utf8(head).ok()?;
    let status_line = text.strip_prefix("HTTP/1.1 ")?.split("\r\n").next()?;
    let (_, code, message) = AUTOMATIC.iter().find(|(s, ..)| *s == status_line)?;
    let empty = text
        .to_ascii_lowercase()
        .contains("\r\ncontent-length: 0\r\n");
    if !empty || !text.ends_with("\r\n\r\n") {
        return None;
    }
    Some(http1_answer(status_line, &error_body(code, message)))
}

impl<T: AsyncRead + Unpin> AsyncRead for JsonErrors<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let result = ready!(Pin::new(&mut self.inner).poll_read(cx, buf));
        let this = &mut *self;
        this.saw(&buf.filled()[before..]);
        Poll::Ready(result)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for JsonErrors<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        // An answer is going out: the request it answers is over.
        self.request_begun = false;
        if self.pending.is_none() {
            if let Some(bytes) = replacement(buf) {
                self.pending = Some((bytes, 0, buf.len()));
            }
        }
        let this = &mut *self;
        let Some((bytes, written, stands_for)) = &mut this.pending else {
            return Pin::new(&mut this.inner).poll_write(cx, buf);
        };
        while *written < bytes.len() {
            match ready!(Pin::new(&mut this.inner).poll_write(cx, &bytes[*written..])) {
                Ok(0) => return Poll::Ready(Err(io::ErrorKind::WriteZero.into())),
                Ok(n) => *written += n,
                Err(e) => return Poll::Ready(Err(e)),
            }
        }
        let n = *stands_for;
        this.pending = None;
        Poll::Ready(Ok(n))
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_hypers_empty_error_heads_are_replaced() {
        let head =
            b"HTTP/1.1 431 Request Header Fields Too Large\r\ncontent-length: 0\r\ndate: x\r\n\r\n";
        let out = String::from_utf8(replacement(head).unwrap()).unwrap();
        assert!(out.starts_with("HTTP/1.1 431 Request Header Fields Too Large\r\n"));
        let body = out.split("\r\n\r\n").nth(1).unwrap();
        let v: serde_json::Value = serde_json::from_str(body).unwrap();
        assert_eq!(v["error"]["code"], "headers_too_large");
        assert!(out.contains(&format!("content-length: {}\r\n", body.len())));
        // A handler's 400 has a body: left alone.
        let ours = b"HTTP/1.1 400 Bad Request\r\ncontent-type: application/json\r\ncontent-length: 20\r\n\r\n{\"error\": {}}";
        assert!(replacement(ours).is_none());
        // Other statuses, and a head followed by a body, are left alone.
        assert!(replacement(b"HTTP/1.1 200 OK\r\ncontent-length: 0\r\n\r\n").is_none());
        assert!(replacement(b"HTTP/1.1 400 Bad Request\r\ncontent-length: 0\r\n\r\nx").is_none());
    }

    #[test]
    fn last_words_answer_http2_and_a_cut_head_but_not_an_idle_connection() {
        let timeout = std::time::Duration::from_secs(10);
        let mut c = JsonErrors::new(());
        assert_eq!(c.last_word(End::HeaderTimeout, timeout), None);
        c.saw(b"GET /healthz HTTP/1.1\r\nhost");
        let answer = String::from_utf8(c.last_word(End::HeaderTimeout, timeout).unwrap()).unwrap();
        assert!(
            answer.starts_with("HTTP/1.1 408 Request Timeout\r\n"),
            "{answer}"
        );
        assert!(answer.contains("\"header_timeout\"") && answer.contains("10000 ms"));
        assert_eq!(c.last_word(End::Other, timeout), None);
        // The preface, even in pieces: SETTINGS then GOAWAY(HTTP_1_1_REQUIRED).
        let mut h2 = JsonErrors::new(());
        h2.saw(b"PRI * HT");
        h2.saw(b"TP/2.0\r\n\r\nSM\r\n\r\n");
        let frames = h2.last_word(End::Other, timeout).unwrap();
        assert_eq!(&frames[..9], &[0, 0, 0, 4, 0, 0, 0, 0, 0]);
        let goaway = &frames[9..];
        let len = u32::from_be_bytes([0, goaway[0], goaway[1], goaway[2]]) as usize;
        assert_eq!((goaway[3], goaway.len()), (7, 9 + len));
        assert_eq!(&goaway[13..17], &[0, 0, 0, 0xd]);
        let debug: serde_json::Value = serde_json::from_slice(&goaway[17..]).unwrap();
        assert_eq!(debug["error"]["code"], "http2_not_supported");
    }
}
