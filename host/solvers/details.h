// Details: the solver-specific results of a solve (cond, iterations, loss curve, ...) as an
// ordered list of named values, without a JSON library (host/report/result_json.h writes them).
#pragma once

#include <concepts>
#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <variant>
#include <vector>

namespace tfm {

class DetailValue;

// Named values in insertion order. `details["x"] = value` adds or replaces an entry.
class Details {
 public:
  using Entry = std::pair<std::string, DetailValue>;

  // The value named `name`, added as null when absent.
  DetailValue& operator[](std::string_view name);
  // The value named `name`; throws std::out_of_range when absent.
  const DetailValue& operator[](std::string_view name) const;
  // nullptr when absent.
  const DetailValue* find(std::string_view name) const;
  bool contains(std::string_view name) const { return find(name) != nullptr; }

  size_t size() const { return entries_.size(); }
  bool empty() const { return entries_.empty(); }
  std::vector<Entry>::const_iterator begin() const { return entries_.begin(); }
  std::vector<Entry>::const_iterator end() const { return entries_.end(); }

  bool operator==(const Details& other) const;

 private:
  std::vector<Entry> entries_;
};

// One value: null, bool, integer (signed or unsigned, as given), number, text, a list of
// numbers or integers, or nested details.
class DetailValue {
 public:
  using Integers = std::vector<int64_t>;
  using Numbers = std::vector<double>;
  using Storage = std::variant<std::monostate, bool, int64_t, uint64_t, double, std::string, Numbers, Integers, Details>;

  DetailValue() = default;
  DetailValue(bool v) : v_(v) {}
  template <std::signed_integral T>
  DetailValue(T v) : v_(int64_t(v)) {}
  template <std::unsigned_integral T>
    requires(!std::same_as<T, bool>)
  DetailValue(T v) : v_(uint64_t(v)) {}
  DetailValue(double v) : v_(v) {}
  DetailValue(float v) : v_(double(v)) {}
  DetailValue(std::string v) : v_(std::move(v)) {}
  DetailValue(const char* v) : v_(std::string(v)) {}
  DetailValue(Numbers v) : v_(std::move(v)) {}
  template <std::integral T>
    requires(!std::same_as<T, bool>)
  DetailValue(const std::vector<T>& v) : v_(Integers(v.begin(), v.end())) {}
  DetailValue(Details v) : v_(std::move(v)) {}

  bool is_null() const { return std::holds_alternative<std::monostate>(v_); }
  bool is_bool() const { return std::holds_alternative<bool>(v_); }
  bool is_integer() const { return std::holds_alternative<int64_t>(v_) || std::holds_alternative<uint64_t>(v_); }
  bool is_number() const { return is_integer() || std::holds_alternative<double>(v_); }  // integer or not
  bool is_text() const { return std::holds_alternative<std::string>(v_); }
  bool is_list() const { return std::holds_alternative<Numbers>(v_) || std::holds_alternative<Integers>(v_); }
  bool is_details() const { return std::holds_alternative<Details>(v_); }

  // The value as T: an arithmetic type (from any number; bool from bool), std::string, Numbers
  // (from either list) or Details. Throws std::runtime_error when the value has another kind.
  template <class T>
  T get() const;

  // Lists: their length; details: their entry count; otherwise 0.
  size_t size() const;
  // Nested details: the entry named `name` (std::out_of_range when absent, std::runtime_error
  // when this value is not nested details).
  const DetailValue& operator[](std::string_view name) const;

  const Storage& storage() const { return v_; }
  bool operator==(const DetailValue& other) const { return v_ == other.v_; }

 private:
  [[noreturn]] void wrong_kind(const char* wanted) const;
  Storage v_;
};

template <class T>
T DetailValue::get() const {
  if constexpr (std::same_as<T, bool>) {
    if (const bool* b = std::get_if<bool>(&v_)) return *b;
    wrong_kind("a bool");
  } else if constexpr (std::is_arithmetic_v<T>) {
    if (const int64_t* i = std::get_if<int64_t>(&v_)) return T(*i);
    if (const uint64_t* u = std::get_if<uint64_t>(&v_)) return T(*u);
    if (const double* d = std::get_if<double>(&v_)) return T(*d);
    wrong_kind("a number");
  } else if constexpr (std::same_as<T, std::string>) {
    if (const std::string* s = std::get_if<std::string>(&v_)) return *s;
    wrong_kind("text");
  } else if constexpr (std::same_as<T, Numbers>) {
    if (const Numbers* n = std::get_if<Numbers>(&v_)) return *n;
    if (const Integers* i = std::get_if<Integers>(&v_)) return Numbers(i->begin(), i->end());
    wrong_kind("a list of numbers");
  } else if constexpr (std::same_as<T, Details>) {
    if (const Details* d = std::get_if<Details>(&v_)) return *d;
    wrong_kind("nested details");
  } else {
    static_assert(sizeof(T) == 0, "DetailValue::get: unsupported type");
  }
}

}  // namespace tfm
