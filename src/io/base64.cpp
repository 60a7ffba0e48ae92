// Streaming base64 decoding: a 256-entry table and group-at-a-time decoding.
#include "io/base64.h"

#include <algorithm>
#include <array>
#include <cstring>

namespace hpray::base64 {
namespace {

constexpr std::uint8_t kWhitespace = 64;
constexpr std::uint8_t kPad = 65;
constexpr std::uint8_t kInvalid = 255;

constexpr std::array<std::uint8_t, 256> MakeTable() {
    std::array<std::uint8_t, 256> t{};
    for (auto& v : t) v = kInvalid;
    const char* alphabet =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    for (int i = 0; i < 64; ++i) t[static_cast<unsigned char>(alphabet[i])] = i;
    t[' '] = t['\n'] = t['\r'] = t['\t'] = t['\f'] = t['\v'] = kWhitespace;
    t['='] = kPad;
    return t;
}
constexpr std::array<std::uint8_t, 256> kTable = MakeTable();

}  // namespace

int Decoder::NextGroup(std::uint8_t group[3]) {
    if (failed_) return 0;
    std::uint32_t sextets[4];
    int count = 0;    // sextets collected
    int padding = 0;  // '=' collected
    std::size_t groupStart = pos_;
    while (pos_ < size_ && count + padding < 4) {
        const std::uint8_t v = kTable[static_cast<unsigned char>(text_[pos_])];
        if (v == kWhitespace) {
            ++pos_;
            continue;
        }
        if (v == kInvalid || (v < 64 && padding > 0)) {
            failed_ = true;
            return 0;
        }
        if (v == kPad) {
            // Padding only after two or three data characters.
            if (count < 2) {
                failed_ = true;
                return 0;
            }
            ++padding;
        } else {
            if (count == 0) groupStart = pos_;
            sextets[count++] = v;
        }
        ++pos_;
    }
    if (count == 0) {
        if (padding > 0) {
            pos_ = groupStart;
            failed_ = true;
        }
        return 0;
    }
    if (count == 1) {  // a lone character cannot encode a byte
        pos_ = groupStart;
        failed_ = true;
        return 0;
    }
    for (int i = count; i < 4; ++i) sextets[i] = 0;
    const std::uint32_t bits =
        (sextets[0] << 18) | (sextets[1] << 12) | (sextets[2] << 6) | sextets[3];
    group[0] = static_cast<std::uint8_t>(bits >> 16);
    group[1] = static_cast<std::uint8_t>(bits >> 8);
    group[2] = static_cast<std::uint8_t>(bits);
    return count - 1;
}

std::size_t Decoder::Decode(std::uint8_t* out, std::size_t n) {
    std::size_t got = 0;
    while (got < n && pendingCount_ > 0) {
        out[got++] = pending_[pendingStart_++];
        --pendingCount_;
    }
    while (got < n) {
        // Fast path: four data characters in a row, no whitespace or padding.
        while (n - got >= 3 && size_ - pos_ >= 4) {
            const std::uint8_t a = kTable[static_cast<unsigned char>(text_[pos_])];
            const std::uint8_t b = kTable[static_cast<unsigned char>(text_[pos_ + 1])];
            const std::uint8_t c = kTable[static_cast<unsigned char>(text_[pos_ + 2])];
            const std::uint8_t d = kTable[static_cast<unsigned char>(text_[pos_ + 3])];
            if ((a | b | c | d) >= 64) break;
            const std::uint32_t bits = (std::uint32_t(a) << 18) |
                                       (std::uint32_t(b) << 12) |
                                       (std::uint32_t(c) << 6) | d;
            out[got] = static_cast<std::uint8_t>(bits >> 16);
            out[got + 1] = static_cast<std::uint8_t>(bits >> 8);
            out[got + 2] = static_cast<std::uint8_t>(bits);
            got += 3;
            pos_ += 4;
        }
        if (got >= n) break;
        // Slow path: one group with whitespace, padding or a short tail.
        std::uint8_t group[3];
        const int len = NextGroup(group);
        if (len == 0) break;
        const int take = static_cast<int>(std::min<std::size_t>(len, n - got));
        std::memcpy(out + got, group, take);
        got += take;
        if (take < len) {
            pendingStart_ = 0;
            pendingCount_ = len - take;
            std::memcpy(pending_, group + take, pendingCount_);
        }
    }
    return got;
}

}  // namespace hpray::base64
