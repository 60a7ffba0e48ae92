// Streaming base64 (RFC 4648) decoding that also accepts separately padded segments.
#pragma once

#include <cstddef>
#include <cstdint>

namespace hpray::base64 {

/// Decodes base64 text incrementally. Whitespace is skipped. A padded group ("xx==",
/// "xxx=") ends a segment and decoding continues with the next group, so the
/// concatenation of separately encoded blocks (VTK writes a compression header and its
/// data as two base64 blocks) decodes to the concatenation of their bytes. The text is
/// borrowed and must outlive the decoder.
class Decoder {
  public:
    Decoder(const char* text, std::size_t size) : text_(text), size_(size) {}

    /// Decodes up to `n` bytes into `out`. Returns the number written; fewer than `n`
    /// only when the text ends or holds an invalid character (then Failed() is true).
    std::size_t Decode(std::uint8_t* out, std::size_t n);

    /// True after an invalid character (or a lone trailing character) was met.
    bool Failed() const { return failed_; }
    /// Index in the text of the next unread character, or of the offending one after a
    /// failure.
    std::size_t Position() const { return pos_; }
    /// An upper bound on the bytes still decodable.
    std::size_t RemainingBound() const {
        return (size_ - pos_) / 4 * 3 + 3 + pendingCount_;
    }

  private:
    /// Decodes the next group of up to 4 characters into `group`; returns its byte count
    /// (0 at the end of the text or on failure).
    int NextGroup(std::uint8_t group[3]);

    const char* text_;
    std::size_t size_;
    std::size_t pos_ = 0;
    std::uint8_t pending_[3] = {0, 0, 0};
    int pendingStart_ = 0;
    int pendingCount_ = 0;
    bool failed_ = false;
};

}  // namespace hpray::base64
