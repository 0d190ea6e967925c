// Details and DetailValue: lookup by name, sizes, comparison.
#include "tfmatch/solvers/details.h"

#include <algorithm>
#include <stdexcept>

namespace tfm {

DetailValue& Details::operator[](std::string_view name) {
  auto it = std::find_if(entries_.begin(), entries_.end(), [&](const Entry& e) { return e.first == name; });
  if (it != entries_.end()) return it->second;
  return entries_.emplace_back(std::string(name), DetailValue()).second;
}

const DetailValue& Details::operator[](std::string_view name) const {
  if (const DetailValue* v = find(name)) return *v;
  throw std::out_of_range("details: no entry '" + std::string(name) + "'");
}

const DetailValue* Details::find(std::string_view name) const {
  auto it = std::find_if(entries_.begin(), entries_.end(), [&](const Entry& e) { return e.first == name; });
  return it == entries_.end() ? nullptr : &it->second;
}

bool Details::operator==(const Details& other) const { return entries_ == other.entries_; }

size_t DetailValue::size() const {
  if (const Numbers* n = std::get_if<Numbers>(&v_)) return n->size();
  if (const Integers* i = std::get_if<Integers>(&v_)) return i->size();
  if (const Details* d = std::get_if<Details>(&v_)) return d->size();
  return 0;
}

const DetailValue& DetailValue::operator[](std::string_view name) const {
  if (const Details* d = std::get_if<Details>(&v_)) return (*d)[name];
  wrong_kind("nested details");
}

void DetailValue::wrong_kind(const char* wanted) const {
  static const char* const kinds[] = {"null", "a bool", "an integer", "an integer", "a number",
                                      "text", "a list of numbers", "a list of integers", "nested details"};
  throw std::runtime_error(std::string("details: expected ") + wanted + ", found " + kinds[v_.index()]);
}

}  // namespace tfm
