// The paper's cuSPARSE assembly of the normal equations, on the Kronecker factor S of
// A = S (x) I_4 (A^T A = S^T S (x) I_4, and A^T b is S^T B for the voxels x 4 matrix B of
// reference colours): S^T S by cusparseSpGEMM, S^T B by cusparseSpMM, from S and S^T built on
// the device (explicit_system.cu), all in double precision. A quarter of the rows and products of
// forming A^T A itself.
#include <chrono>

#include "tfmatch/cuda/cuda_common.cuh"

namespace tfm::cuda {

namespace {

// The default SpGEMM. CUSPARSE_SPGEMM_CSR_ALG_DETERMINITIC failed with "internal error" in the
// size query of cusparseSpGEMM_compute on an H100 (CUDA 13.0): that algorithm wants the
// cusparseSpGEMMreuse_* calls. The test NormalEquationsMatchExactSolution checks that two runs
// give the same TF bits.
constexpr cusparseSpGEMMAlg_t kAlg = CUSPARSE_SPGEMM_DEFAULT;

// C = a^T a from a and its transpose `at`, with the three-phase SpGEMM (work estimation, compute,
// copy into sized arrays).
DeviceCsr spgemm_ata(cusparseHandle_t handle, const DeviceCsr& at, const DeviceCsr& a) {
  const double one = 1.0, zero = 0.0;
  const cusparseOperation_t op = CUSPARSE_OPERATION_NON_TRANSPOSE;
  SpMat mat_at(at), mat_a(a), mat_c(at.rows, a.cols);
  cusparseSpGEMMDescr_t desc = nullptr;
  check(cusparseSpGEMM_createDescr(&desc), "cusparseSpGEMM_createDescr");
  struct Guard {
    cusparseSpGEMMDescr_t d;
    ~Guard() { cusparseSpGEMM_destroyDescr(d); }
  } guard{desc};
  size_t bytes1 = 0, bytes2 = 0;
  check(cusparseSpGEMM_workEstimation(handle, op, op, &one, mat_at.d, mat_a.d, &zero, mat_c.d, CUDA_R_64F,
                                      kAlg, desc, &bytes1, nullptr),
        "cusparseSpGEMM_workEstimation (size)");
  DeviceArray<char> buffer1(bytes1);
  check(cusparseSpGEMM_workEstimation(handle, op, op, &one, mat_at.d, mat_a.d, &zero, mat_c.d, CUDA_R_64F,
                                      kAlg, desc, &bytes1, buffer1.get()),
        "cusparseSpGEMM_workEstimation");
  check(cusparseSpGEMM_compute(handle, op, op, &one, mat_at.d, mat_a.d, &zero, mat_c.d, CUDA_R_64F,
                               kAlg, desc, &bytes2, nullptr),
        "cusparseSpGEMM_compute (size)");
  DeviceArray<char> buffer2(bytes2);
  check(cusparseSpGEMM_compute(handle, op, op, &one, mat_at.d, mat_a.d, &zero, mat_c.d, CUDA_R_64F,
                               kAlg, desc, &bytes2, buffer2.get()),
        "cusparseSpGEMM_compute");
  int64_t rows = 0, cols = 0, nnz = 0;
  check(cusparseSpMatGetSize(mat_c.d, &rows, &cols, &nnz), "cusparseSpMatGetSize");
  DeviceCsr c;
  c.rows = int(rows);
  c.cols = int(cols);
  c.nnz = nnz;
  c.row_ptr = DeviceArray<int>(size_t(rows) + 1);
  c.col = DeviceArray<int>(size_t(nnz));
  c.val = DeviceArray<double>(size_t(nnz));
  check(cusparseCsrSetPointers(mat_c.d, c.row_ptr.get(), c.col.get(), c.val.get()), "cusparseCsrSetPointers");
  check(cusparseSpGEMM_copy(handle, op, op, &one, mat_at.d, mat_a.d, &zero, mat_c.d, CUDA_R_64F,
                            kAlg, desc),
        "cusparseSpGEMM_copy");
  return c;
}

}  // namespace

CusparseAssembly assemble_cusparse(const SystemOnDevice& sys) {
  if (sys.voxels() == 0) throw std::invalid_argument("assemble_cusparse: no voxel has data in both fields");
  CusparseAssembly out;
  SparseHandle handle;
  EventTimer timer;
  timer.start();
  const DeviceCsr c = spgemm_ata(handle, sys.st, sys.s);
  DeviceArray<double> stb(4 * size_t(sys.n));
  DeviceArray<char> buffer;
  spmm(handle, SpMat(sys.st), DnMat(sys.s.rows, 4, sys.b.get()), DnMat(sys.n, 4, stb.get()), buffer);
  out.assemble_ms = timer.stop();

  out.row_ptr = c.row_ptr.download();
  out.col = c.col.download();
  out.val = c.val.download();
  out.stb = stb.download();
  return out;
}

}  // namespace tfm::cuda
