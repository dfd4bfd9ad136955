#pragma once
// A small parser for "--key value" and "--flag" command lines, with errors that name the option.
#include <map>
#include <set>
#include <string>
#include <vector>

namespace affinity::cli {

class Arguments {
public:
    // `options` take a value, `flags` do not; anything else is an error.
    Arguments(const std::vector<std::string>& args, const std::set<std::string>& options,
              const std::set<std::string>& flags);

    bool has(const std::string& name) const { return values_.count(name) > 0; }
    bool flag(const std::string& name) const { return flags_.count(name) > 0; }
    std::string text(const std::string& name) const;  // required
    std::string text(const std::string& name, const std::string& fallback) const;
    int integer(const std::string& name, int fallback, int lo, int hi) const;
    unsigned long long unsignedInteger(const std::string& name, unsigned long long fallback) const;
    // "WxH" with both in [1, 16384].
    void size(const std::string& name, int& width, int& height) const;

private:
    std::map<std::string, std::string> values_;
    std::set<std::string> flags_;
};

}  // namespace affinity::cli
