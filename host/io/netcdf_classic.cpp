// Size of a classic NetCDF file's header and data (layout from the NetCDF classic format
// specification: magic, numrecs, dim_list, gatt_list, var_list, then the data).
#include "tfmatch/io/netcdf_classic.h"

#include <netcdf.h>

#include <algorithm>
#include <stdexcept>
#include <vector>

namespace tfm {
namespace {

uint64_t pad4(uint64_t n) { return (n + 3) / 4 * 4; }

struct Sizes {
  uint64_t non_neg;  // NON_NEG and nelems: 4 bytes, 8 in CDF-5
  uint64_t offset;   // a variable's begin: 4 bytes in CDF-1, 8 otherwise
};

bool name_size(int nc, int var, int att_or_dim, bool is_att, const Sizes& s, uint64_t& out) {
  char name[NC_MAX_NAME + 1];
  int rc = is_att ? nc_inq_attname(nc, var, att_or_dim, name) : nc_inq_dimname(nc, att_or_dim, name);
  if (rc != NC_NOERR) return false;
  uint64_t len = 0;
  while (name[len]) ++len;
  out = s.non_neg + pad4(len);
  return true;
}

// A list of attributes (ABSENT, or tag + nelems + the attributes).
bool attributes_size(int nc, int var, const Sizes& s, uint64_t& out) {
  int natts = 0;
  if ((var == NC_GLOBAL ? nc_inq_natts(nc, &natts) : nc_inq_varnatts(nc, var, &natts)) != NC_NOERR) return false;
  out = 4 + s.non_neg;
  for (int a = 0; a < natts; ++a) {
    char name[NC_MAX_NAME + 1];
    nc_type t;
    size_t len = 0, tsize = 0;
    uint64_t n = 0;
    if (nc_inq_attname(nc, var, a, name) != NC_NOERR || nc_inq_att(nc, var, name, &t, &len) != NC_NOERR ||
        nc_inq_type(nc, t, nullptr, &tsize) != NC_NOERR || !name_size(nc, var, a, true, s, n))
      return false;
    out += n + 4 + s.non_neg + pad4(uint64_t(len) * tsize);
  }
  return true;
}

// The header walk: a cursor that refuses to go past the end of the file.
class HeaderCursor {
 public:
  HeaderCursor(const ByteReader& read, uint64_t size, const std::string& name, const Sizes& s)
      : read_(read), size_(size), name_(name), s_(s) {}
  uint64_t left() const { return size_ - pos_; }
  // What is wrong at the cursor; `past_end`: something there runs past the file's end, whose size
  // the message then gives (a wrong value well inside the file is not "beyond" it).
  [[noreturn]] void fail(const std::string& what, bool past_end = false) const {
    throw std::runtime_error(name_ + ": NetCDF header: " + what + " at byte " + std::to_string(pos_) +
                             (past_end ? " of the file's " + std::to_string(size_) + " bytes" : std::string()));
  }
  uint64_t number(uint64_t bytes, const char* what) {
    unsigned char b[8];
    if (bytes > left() || !read_(pos_, bytes, reinterpret_cast<char*>(b))) fail(std::string(what) + " ends the file", true);
    pos_ += bytes;
    uint64_t v = 0;
    for (uint64_t i = 0; i < bytes; ++i) v = (v << 8) | b[i];  // big-endian
    return v;
  }
  uint64_t count() { return number(s_.non_neg, "a count"); }
  // Skips `n` bytes of which each element needs `each` at least: the count must fit.
  void skip(uint64_t n, uint64_t each, const std::string& what) {
    if (each > 0 && n > left() / each) fail(what + " (" + std::to_string(n) + " of them) need more bytes than are left", true);
    pos_ += pad4(n * each);
    if (pos_ > size_) fail(what + " run past the end", true);
  }
  // netCDF-C copies names into buffers of NC_MAX_NAME + 1 bytes (its own and tfmatch's) without
  // checking what the file says: a longer name overflows them.
  void name(const char* of) {
    const uint64_t n = count();
    if (n > NC_MAX_NAME)
      fail(std::string("the name of ") + of + " has " + std::to_string(n) + " bytes, more than netCDF's " +
           std::to_string(NC_MAX_NAME));
    skip(n, 1, std::string("the name of ") + of);
  }
  // A classic external type: 1..6, and 7..11 in CDF-5 (netCDF-C divides by a type's size).
  uint64_t type(const char* of) {
    const uint64_t t = number(4, of);
    if (t < 1 || t > (s_.non_neg == 8 ? 11u : 6u)) fail(std::string(of) + " " + std::to_string(t) + " is not a classic type");
    return t;
  }
  // A list (dim, att or var) that is ABSENT or `tag` + nelems; returns nelems, checked against the
  // least bytes one element takes.
  uint64_t list(uint32_t tag, uint64_t least_each, const char* what) {
    const uint64_t t = number(4, what), n = count();
    if (t == 0 && n == 0) return 0;
    if (t != tag) fail(std::string(what) + " has tag " + std::to_string(t));
    if (n > left() / least_each) fail(std::string(what) + " claims " + std::to_string(n) + " entries, more than the bytes left hold", true);
    return n;
  }
  void attributes() {
    const uint64_t n = list(0x0C, 4 + s_.non_neg + 4 + s_.non_neg, "an attribute list");
    for (uint64_t a = 0; a < n; ++a) {
      name("an attribute");
      static const uint64_t sizes[] = {0, 1, 1, 2, 4, 4, 8, 1, 2, 4, 8, 8};  // NC_BYTE .. NC_UINT64
      skip(count(), sizes[type("an attribute type")], "attribute values");
    }
  }

 private:
  const ByteReader& read_;
  uint64_t size_;
  const std::string& name_;
  Sizes s_;
  uint64_t pos_ = 0;
};

}  // namespace

void check_netcdf_classic_header(const ByteReader& read, uint64_t size, const std::string& name) {
  char magic[4];
  if (size < 4 || !read(0, 4, magic) || magic[0] != 'C' || magic[1] != 'D' || magic[2] != 'F') return;
  if (magic[3] != 1 && magic[3] != 2 && magic[3] != 5) return;  // netCDF-C says what is wrong
  const Sizes s{magic[3] == 5 ? 8u : 4u, magic[3] == 1 ? 4u : 8u};
  HeaderCursor c(read, size, name, s);
  c.number(4, "the magic number");
  c.count();  // numrecs
  const uint64_t dims = c.list(0x0A, s.non_neg + s.non_neg, "the dimension list");
  std::vector<bool> record(dims);  // length 0: the unlimited (record) dimension, at most one
  for (uint64_t d = 0; d < dims; ++d) {
    c.name("a dimension");
    record[d] = c.count() == 0;
    if (record[d] && std::count(record.begin(), record.begin() + ptrdiff_t(d), true) > 0)
      c.fail("a second dimension of length 0 (only one unlimited dimension is allowed)");
  }
  c.attributes();  // global attributes
  const uint64_t vars = c.list(0x0B, 4 * s.non_neg + 8 + s.offset, "the variable list");
  for (uint64_t v = 0; v < vars; ++v) {
    c.name("a variable");
    // Its dimensions exist, and the unlimited one comes first (netCDF-C sizes a variable by
    // dividing by the product of its other dimensions, which must not be 0).
    const uint64_t ndims = c.count();
    if (ndims > NC_MAX_VAR_DIMS) c.fail("a variable with " + std::to_string(ndims) + " dimensions");
    for (uint64_t k = 0; k < ndims; ++k) {
      const uint64_t id = c.number(s.non_neg, "a dimension id");
      if (id >= dims) c.fail("a variable names dimension " + std::to_string(id) + " of " + std::to_string(dims));
      if (k > 0 && record[id]) c.fail("a variable has the unlimited dimension in position " + std::to_string(k));
    }
    c.attributes();
    c.type("a variable type");
    c.number(s.non_neg, "a variable size");
    c.number(s.offset, "a variable offset");
  }
}

uint64_t netcdf_classic_minimum_size(int nc, int format) {
  constexpr uint64_t kLimit = uint64_t(1) << 62;
  if (format != NC_FORMAT_CLASSIC && format != NC_FORMAT_64BIT_OFFSET && format != NC_FORMAT_CDF5) return 0;
  const Sizes s{format == NC_FORMAT_CDF5 ? 8u : 4u, format == NC_FORMAT_CLASSIC ? 4u : 8u};
  int ndims = 0, nvars = 0, unlimited = -1;
  if (nc_inq(nc, &ndims, &nvars, nullptr, &unlimited) != NC_NOERR) return 0;
  uint64_t size = 4 + s.non_neg;  // magic, numrecs
  size += 4 + s.non_neg;          // dim_list
  std::vector<uint64_t> dim_len(ndims);
  for (int d = 0; d < ndims; ++d) {
    size_t len = 0;
    uint64_t n = 0;
    if (nc_inq_dimlen(nc, d, &len) != NC_NOERR || !name_size(nc, NC_GLOBAL, d, false, s, n)) return 0;
    dim_len[d] = len;
    size += n + s.non_neg;
  }
  uint64_t atts = 0;
  if (!attributes_size(nc, NC_GLOBAL, s, atts)) return 0;
  size += atts + 4 + s.non_neg;  // gatt_list, var_list
  uint64_t data = 0, record = 0;
  for (int v = 0; v < nvars; ++v) {
    char name[NC_MAX_NAME + 1];
    nc_type t;
    int nd = 0;
    int dims[NC_MAX_VAR_DIMS];
    size_t tsize = 0;
    if (nc_inq_var(nc, v, name, &t, &nd, dims, nullptr) != NC_NOERR || nc_inq_type(nc, t, nullptr, &tsize) != NC_NOERR ||
        !attributes_size(nc, v, s, atts))
      return 0;
    uint64_t len = 0;
    while (name[len]) ++len;
    size += s.non_neg + pad4(len) + s.non_neg + uint64_t(nd) * s.non_neg + atts + 4 + s.non_neg + s.offset;
    // Data: one value per index, without padding (a lower bound); record variables per record.
    // A size past 2^62 bytes is more than any file holds: kNetcdfSizeOverflow, never a wrapped
    // (small) number or 0, which would pass a truncated file.
    uint64_t count = tsize;
    bool is_record = nd > 0 && dims[0] == unlimited;
    for (int i = is_record ? 1 : 0; i < nd; ++i) {
      if (dim_len[dims[i]] != 0 && count > kLimit / dim_len[dims[i]]) return kNetcdfSizeOverflow;
      count *= dim_len[dims[i]];
    }
    uint64_t& sum = is_record ? record : data;
    sum += count;
    if (sum > kLimit) return kNetcdfSizeOverflow;
  }
  const uint64_t records = unlimited >= 0 ? dim_len[unlimited] : 0;
  if (records != 0 && record > kLimit / records) return kNetcdfSizeOverflow;
  const uint64_t total = size + data + records * record;  // each term <= 2^62: no wrap
  return total > kLimit ? kNetcdfSizeOverflow : total;
}

}  // namespace tfm
