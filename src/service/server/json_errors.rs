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
}

impl<T> JsonErrors<T> {
    /// Wrap a connection.
    pub fn new(inner: T) -> Self {
        JsonErrors {
            inner,
            pending: None,
        }
    }
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
    let body =
        serde_json::json!({"error": {"code": code, "message": message, "field": null}}).to_string();
    Some(
        format!(
            "HTTP/1.1 {status_line}\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{body}",
            body.len()
        )
        .into_bytes(),
    )
}

impl<T: AsyncRead + Unpin> AsyncRead for JsonErrors<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for JsonErrors<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
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
}
