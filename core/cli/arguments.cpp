#include "arguments.h"

#include <charconv>

#include "affinity/error.h"

namespace affinity::cli {

Arguments::Arguments(const std::vector<std::string>& args, const std::set<std::string>& options,
                     const std::set<std::string>& flags) {
    for (std::size_t i = 0; i < args.size(); ++i) {
        const std::string& arg = args[i];
        if (flags.count(arg)) {
            flags_.insert(arg);
        } else if (options.count(arg)) {
            if (i + 1 >= args.size()) throw Error("option " + arg + " needs a value");
            values_[arg] = args[++i];
        } else {
            throw Error("unknown option '" + arg + "'");
        }
    }
}

std::string Arguments::text(const std::string& name) const {
    auto it = values_.find(name);
    if (it == values_.end()) throw Error("option " + name + " is required");
    return it->second;
}

std::string Arguments::text(const std::string& name, const std::string& fallback) const {
    auto it = values_.find(name);
    return it == values_.end() ? fallback : it->second;
}

int Arguments::integer(const std::string& name, int fallback, int lo, int hi) const {
    auto it = values_.find(name);
    if (it == values_.end()) return fallback;
    int value = 0;
    const std::string& s = it->second;
    auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (error != std::errc() || end != s.data() + s.size())
        throw Error("option " + name + " expects an integer, got '" + s + "'");
    if (value < lo || value > hi)
        throw Error("option " + name + " must be in " + std::to_string(lo) + ".." + std::to_string(hi) + ", got " + s);
    return value;
}

unsigned long long Arguments::unsignedInteger(const std::string& name, unsigned long long fallback) const {
    auto it = values_.find(name);
    if (it == values_.end()) return fallback;
    unsigned long long value = 0;
    const std::string& s = it->second;
    auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (error != std::errc() || end != s.data() + s.size())
        throw Error("option " + name + " expects a non-negative integer, got '" + s + "'");
    return value;
}

void Arguments::size(const std::string& name, int& width, int& height) const {
    auto it = values_.find(name);
    if (it == values_.end()) return;
    const std::string& s = it->second;
    std::size_t x = s.find('x');
    auto parse = [&](const char* begin, const char* end, int& out) {
        auto [stop, error] = std::from_chars(begin, end, out);
        return error == std::errc() && stop == end;
    };
    int w = 0, h = 0;
    if (x == std::string::npos || !parse(s.data(), s.data() + x, w) ||
        !parse(s.data() + x + 1, s.data() + s.size(), h) || w < 1 || h < 1 || w > 16384 || h > 16384)
        throw Error("option " + name + " expects WIDTHxHEIGHT with both in 1..16384, got '" + s + "'");
    width = w;
    height = h;
}

}  // namespace affinity::cli
