// Built-in data sets (placeholder while the generators are written).
#include "mesh/builtin.h"
#include "util/error.h"
namespace hpray {
Mesh MakeBuiltin(const std::string& spec) { throw InputError(spec, "", "unknown builtin"); }
std::vector<std::string> BuiltinNames() { return {}; }
}  // namespace hpray
