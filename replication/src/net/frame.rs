//! Length-prefixed frames on a QUIC stream: `[u32 big-endian length][body]`, each body one
//! sync message, and one frame a stream. The length is checked against [`MAX_FRAME_BYTES`] before anything is
//! allocated, so a hostile peer cannot make a node reserve more than one frame's worth.

use crate::sync::message::MAX_MESSAGE_BYTES;

/// Bytes of the length prefix.
pub const FRAME_HEADER_BYTES: usize = 4;
/// Largest frame body: one sync message at its limit.
pub const MAX_FRAME_BYTES: usize = MAX_MESSAGE_BYTES;

/// Why a frame could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    /// The announced (or offered) length is over [`MAX_FRAME_BYTES`].
    #[error("frame of {0} bytes, over the limit {MAX_FRAME_BYTES}")]
    TooLarge(u64),
    /// The stream ended in the middle of a frame.
    #[error("stream ended inside a frame")]
    Truncated,
    /// The stream went on after its one frame.
    #[error("more bytes after the stream's frame")]
    Trailing,
    /// The stream or its connection failed while reading.
    #[error(transparent)]
    Read(#[from] quinn::ReadError),
    /// The stream or its connection failed while writing.
    #[error(transparent)]
    Write(#[from] quinn::WriteError),
}

/// `body` with its length prefix, ready to write.
pub fn encode_frame(body: &[u8]) -> Result<Vec<u8>, FrameError> {
    let len = u32::try_from(body.len())
        .ok()
        .filter(|&len| len as usize <= MAX_FRAME_BYTES)
        .ok_or(FrameError::TooLarge(body.len() as u64))?;
    let mut out = Vec::with_capacity(FRAME_HEADER_BYTES + body.len());
    out.extend_from_slice(&len.to_be_bytes());
    out.extend_from_slice(body);
    Ok(out)
}

/// Writes one frame.
pub async fn write_frame(stream: &mut quinn::SendStream, body: &[u8]) -> Result<(), FrameError> {
    let frame = encode_frame(body)?;
    stream.write_all(&frame).await?;
    Ok(())
}

/// Reads one frame; `Ok(None)` when the stream finished cleanly between frames.
pub async fn read_frame(stream: &mut quinn::RecvStream) -> Result<Option<Vec<u8>>, FrameError> {
    let mut header = [0; FRAME_HEADER_BYTES];
    match stream.read_exact(&mut header).await {
        Ok(()) => {}
        Err(quinn::ReadExactError::FinishedEarly(0)) => return Ok(None),
        Err(quinn::ReadExactError::FinishedEarly(_)) => return Err(FrameError::Truncated),
        Err(quinn::ReadExactError::ReadError(e)) => return Err(e.into()),
    }
    let len = u32::from_be_bytes(header);
    if len as usize > MAX_FRAME_BYTES {
        return Err(FrameError::TooLarge(u64::from(len)));
    }
    let mut body = vec![0; len as usize];
    match stream.read_exact(&mut body).await {
        Ok(()) => Ok(Some(body)),
        Err(quinn::ReadExactError::FinishedEarly(_)) => Err(FrameError::Truncated),
        Err(quinn::ReadExactError::ReadError(e)) => Err(e.into()),
    }
}

/// Reads a stream that carries one frame, whole: its frame, or an error if it ends before
/// one or goes on after it.
pub async fn read_one_frame(mut stream: quinn::RecvStream) -> Result<Vec<u8>, FrameError> {
    let body = read_frame(&mut stream)
        .await?
        .ok_or(FrameError::Truncated)?;
    let mut rest = [0; 1];
    match stream.read(&mut rest).await? {
        None => Ok(body),
        Some(_) => Err(FrameError::Trailing),
    }
}

/// Writes `body` as the one frame of a new unidirectional stream of `connection`, and
/// finishes the stream.
pub async fn write_one_frame(
    connection: &quinn::Connection,
    body: &[u8],
) -> Result<(), FrameError> {
    let mut stream = connection
        .open_uni()
        .await
        .map_err(|e| FrameError::Write(e.into()))?;
    write_frame(&mut stream, body).await?;
    // Only a stream already reset or stopped cannot finish; its connection says why.
    let _ = stream.finish();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_carry_their_length_and_refuse_oversized_bodies() {
        let frame = encode_frame(b"abc").unwrap();
        assert_eq!(frame, [0, 0, 0, 3, b'a', b'b', b'c']);
        assert_eq!(encode_frame(&[]).unwrap(), [0, 0, 0, 0]);
        assert!(encode_frame(&vec![0; MAX_FRAME_BYTES]).is_ok());
        assert!(matches!(
            encode_frame(&vec![0; MAX_FRAME_BYTES + 1]),
            Err(FrameError::TooLarge(n)) if n == MAX_FRAME_BYTES as u64 + 1
        ));
    }
}
