// Error types: InputError for bad user input (exit 2), InternalError for bugs (exit 1).
#pragma once

#include <stdexcept>
#include <string>

namespace hpray {

/// Bad input (a file, a scene key, a command-line value). `main` catches it once and exits 2.
/// The message always names the source (file path, or "scene" / "command line") and the
/// position inside it (line, byte offset, XML element or key path) when one is known.
class InputError : public std::runtime_error {
public:
    /// `source`: file path or other origin; `where`: position inside it ("line 12",
    /// "byte 4096", "<DataArray Name=\"u\">", "camera.fov_y"), may be empty.
    InputError(const std::string& source, const std::string& where, const std::string& what)
        : std::runtime_error(Format(source, where, what)),
          source_(source), where_(where), what_(what) {}

    const std::string& source() const { return source_; }
    const std::string& where() const { return where_; }
    const std::string& detail() const { return what_; }

private:
    static std::string Format(const std::string& s, const std::string& w,
                              const std::string& m) {
        std::string out = s;
        if (!w.empty()) out += (out.empty() ? "" : ": ") + w;
        out += (out.empty() ? "" : ": ") + m;
        return out;
    }
    std::string source_, where_, what_;
};

/// A violated internal invariant: a bug in hpray, not in the input. Exit 1.
class InternalError : public std::logic_error {
public:
    using std::logic_error::logic_error;
};

/// A requested feature that does not exist yet. Treated as bad input (exit 2).
class NotImplementedError : public InputError {
public:
    explicit NotImplementedError(const std::string& what)
        : InputError("hpray", "", what + " is not implemented yet") {}
};

}  // namespace hpray
