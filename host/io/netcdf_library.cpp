// The netCDF-C functions tfmatch calls, loaded on first use (lazy_library.h): each definition
// matches netcdf.h's declaration (the compiler checks it) and forwards to the library's own.
#include <netcdf.h>
#include <netcdf_mem.h>

#include "tfmatch/io/lazy_library.h"

namespace {
tfm::LazyLibrary& netcdf() {
  static tfm::LazyLibrary library(TFM_NETCDF_SONAME, TFM_NETCDF_DIR, "netCDF-C (Debian: libnetcdf19)");
  return library;
}
}  // namespace

#define FORWARD(name, ...) TFM_LAZY_FORWARD(netcdf(), name, __VA_ARGS__)

extern "C" {

int nc_open(const char* path, int mode, int* ncidp) { FORWARD(nc_open, path, mode, ncidp) }
int nc_open_mem(const char* path, int mode, size_t size, void* memory, int* ncidp) {
  FORWARD(nc_open_mem, path, mode, size, memory, ncidp)
}
int nc_close(int ncid) { FORWARD(nc_close, ncid) }
const char* nc_strerror(int ncerr) { FORWARD(nc_strerror, ncerr) }
int nc_inq(int ncid, int* ndimsp, int* nvarsp, int* nattsp, int* unlimdimidp) {
  FORWARD(nc_inq, ncid, ndimsp, nvarsp, nattsp, unlimdimidp)
}
int nc_inq_format(int ncid, int* formatp) { FORWARD(nc_inq_format, ncid, formatp) }
int nc_inq_grps(int ncid, int* numgrps, int* ncids) { FORWARD(nc_inq_grps, ncid, numgrps, ncids) }
int nc_inq_natts(int ncid, int* nattsp) { FORWARD(nc_inq_natts, ncid, nattsp) }
int nc_inq_nvars(int ncid, int* nvarsp) { FORWARD(nc_inq_nvars, ncid, nvarsp) }
int nc_inq_unlimdims(int ncid, int* nunlimdimsp, int* unlimdimidsp) {
  FORWARD(nc_inq_unlimdims, ncid, nunlimdimsp, unlimdimidsp)
}
int nc_inq_type(int ncid, nc_type xtype, char* name, size_t* size) { FORWARD(nc_inq_type, ncid, xtype, name, size) }
int nc_inq_dim(int ncid, int dimid, char* name, size_t* lenp) { FORWARD(nc_inq_dim, ncid, dimid, name, lenp) }
int nc_inq_dimids(int ncid, int* ndims, int* dimids, int include_parents) {
  FORWARD(nc_inq_dimids, ncid, ndims, dimids, include_parents)
}
int nc_inq_dimlen(int ncid, int dimid, size_t* lenp) { FORWARD(nc_inq_dimlen, ncid, dimid, lenp) }
int nc_inq_dimname(int ncid, int dimid, char* name) { FORWARD(nc_inq_dimname, ncid, dimid, name) }
int nc_inq_var(int ncid, int varid, char* name, nc_type* xtypep, int* ndimsp, int* dimidsp, int* nattsp) {
  FORWARD(nc_inq_var, ncid, varid, name, xtypep, ndimsp, dimidsp, nattsp)
}
int nc_inq_varid(int ncid, const char* name, int* varidp) { FORWARD(nc_inq_varid, ncid, name, varidp) }
int nc_inq_vardimid(int ncid, int varid, int* dimidsp) { FORWARD(nc_inq_vardimid, ncid, varid, dimidsp) }
int nc_inq_varnatts(int ncid, int varid, int* nattsp) { FORWARD(nc_inq_varnatts, ncid, varid, nattsp) }
int nc_inq_varndims(int ncid, int varid, int* ndimsp) { FORWARD(nc_inq_varndims, ncid, varid, ndimsp) }
int nc_inq_vartype(int ncid, int varid, nc_type* xtypep) { FORWARD(nc_inq_vartype, ncid, varid, xtypep) }
int nc_inq_att(int ncid, int varid, const char* name, nc_type* xtypep, size_t* lenp) {
  FORWARD(nc_inq_att, ncid, varid, name, xtypep, lenp)
}
int nc_inq_attname(int ncid, int varid, int attnum, char* name) { FORWARD(nc_inq_attname, ncid, varid, attnum, name) }
int nc_get_att_double(int ncid, int varid, const char* name, double* ip) {
  FORWARD(nc_get_att_double, ncid, varid, name, ip)
}
int nc_get_att_text(int ncid, int varid, const char* name, char* ip) { FORWARD(nc_get_att_text, ncid, varid, name, ip) }
int nc_get_att_string(int ncid, int varid, const char* name, char** ip) {
  FORWARD(nc_get_att_string, ncid, varid, name, ip)
}
int nc_free_string(size_t len, char** data) { FORWARD(nc_free_string, len, data) }
int nc_get_var_double(int ncid, int varid, double* ip) { FORWARD(nc_get_var_double, ncid, varid, ip) }
int nc_get_vara_double(int ncid, int varid, const size_t* startp, const size_t* countp, double* ip) {
  FORWARD(nc_get_vara_double, ncid, varid, startp, countp, ip)
}

}  // extern "C"
