#pragma once
// Error kinds and the exit codes they map to (DESIGN.md: 0 ok, 2 bad input or
// usage, 1 internal error).
#include <stdexcept>
#include <string>

namespace rtlab {

enum class ExitCode : int { Ok = 0, Internal = 1, BadInput = 2 };

// Bad input or usage: the CLI prints what() as one line and exits with 2.
// `where` names the file (or option) at fault; `what` says what is wrong.
class InputError : public std::runtime_error {
public:
    InputError(const std::string& where, const std::string& what)
        : std::runtime_error(where.empty() ? what : where + ": " + what) {}
    explicit InputError(const std::string& what) : std::runtime_error(what) {}
};

}  // namespace rtlab
