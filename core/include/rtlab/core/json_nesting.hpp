#pragma once
// How deeply a JSON text nests its arrays and objects, counted without
// parsing (strings and escapes skipped): the readers of scene, glTF, study
// and RT-core files refuse deep nesting before a parser builds it (memory
// or stack that grows with the depth).
#include <algorithm>
#include <cstddef>
#include <string_view>

namespace rtlab {

// The nesting depth rtlab's JSON files may have (glTF nests < 10 deep, the others less).
inline constexpr std::size_t kMaxJsonNesting = 128;

inline std::size_t jsonNestingDepth(std::string_view text) {
    std::size_t depth = 0, deepest = 0;
    bool inString = false, escaped = false;
    for (const char c : text) {
        if (inString) {
            if (escaped) escaped = false;
            else if (c == '\\') escaped = true;
            else if (c == '"') inString = false;
        } else if (c == '"') {
            inString = true;
        } else if (c == '{' || c == '[') {
            deepest = std::max(deepest, ++depth);
        } else if ((c == '}' || c == ']') && depth > 0) {
            --depth;
        }
    }
    return deepest;
}

}  // namespace rtlab
