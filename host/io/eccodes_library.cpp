// The ecCodes functions tfmatch calls, loaded on first use (lazy_library.h): each definition
// matches eccodes.h's declaration (the compiler checks it) and forwards to the library's own.
#include <eccodes.h>

#include "tfmatch/io/lazy_library.h"

namespace {
tfm::LazyLibrary& eccodes() {
  static tfm::LazyLibrary library(TFM_ECCODES_SONAME, TFM_ECCODES_DIR, "ecCodes (Debian: libeccodes0)");
  return library;
}
}  // namespace

#define FORWARD(name, ...) TFM_LAZY_FORWARD(eccodes(), name, __VA_ARGS__)

extern "C" {

codes_handle* codes_handle_new_from_file(codes_context* c, FILE* f, ProductKind product, int* error) {
  FORWARD(codes_handle_new_from_file, c, f, product, error)
}
int codes_handle_delete(codes_handle* h) { FORWARD(codes_handle_delete, h) }
void codes_grib_multi_support_on(codes_context* c) { FORWARD(codes_grib_multi_support_on, c) }
void codes_grib_multi_support_reset_file(codes_context* c, FILE* f) {
  FORWARD(codes_grib_multi_support_reset_file, c, f)
}
const char* codes_get_error_message(int code) { FORWARD(codes_get_error_message, code) }
int codes_is_missing(const codes_handle* h, const char* key, int* err) { FORWARD(codes_is_missing, h, key, err) }
int codes_get_size(const codes_handle* h, const char* key, size_t* size) { FORWARD(codes_get_size, h, key, size) }
int codes_get_long(const codes_handle* h, const char* key, long* value) { FORWARD(codes_get_long, h, key, value) }
int codes_get_double(const codes_handle* h, const char* key, double* value) {
  FORWARD(codes_get_double, h, key, value)
}
int codes_get_double_array(const codes_handle* h, const char* key, double* vals, size_t* length) {
  FORWARD(codes_get_double_array, h, key, vals, length)
}
int codes_get_string(const codes_handle* h, const char* key, char* mesg, size_t* length) {
  FORWARD(codes_get_string, h, key, mesg, length)
}
int codes_set_double(codes_handle* h, const char* key, double val) { FORWARD(codes_set_double, h, key, val) }

}  // extern "C"
