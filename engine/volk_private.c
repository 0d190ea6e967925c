/* Debian's volk.c, compiled with every global renamed to tfm_volk_* (engine/volk_rename.cmake):
 * the renaming header must come before volk.c includes volk.h. */
#include "tfm_volk_rename.h"
#include <volk.c>
