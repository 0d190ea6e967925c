// The paper's cuSPARSE assembly: A^T (cusparseCsr2cscEx2), A^T A (cusparseSpGEMM, generic API)
// and A^T b (cusparseSpMV) from the explicit CSR A, all in double precision.
#include <chrono>

#include "cuda_common.cuh"

namespace tfm::cuda {

namespace {

// The default SpGEMM. CUSPARSE_SPGEMM_CSR_ALG_DETERMINITIC failed with "internal error" in the
// size query of cusparseSpGEMM_compute on an H100 (CUDA 13.0): that algorithm wants the
// cusparseSpGEMMreuse_* calls. The test NormalEquationsMatchExactSolution checks that two runs
// give the same TF bits.
constexpr cusparseSpGEMMAlg_t kAlg = CUSPARSE_SPGEMM_DEFAULT;

// C = A^T A with the three-phase SpGEMM (work estimation, compute, copy into sized arrays).
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

// CSR algorithm 2: bit-identical results on every run for the non-transposed product (the only one
// used here; A^T is formed explicitly). The default split A^T's long rows across blocks and gave
// cuda-cgls different bits from run to run on an H100 (CUDA 13.0).
constexpr cusparseSpMVAlg_t kSpmvAlg = CUSPARSE_SPMV_CSR_ALG2;

void spmv(cusparseHandle_t handle, const SpMat& m, const DnVec& x, const DnVec& y, DeviceArray<char>& buffer) {
  const double one = 1.0, zero = 0.0;
  size_t bytes = 0;
  check(cusparseSpMV_bufferSize(handle, CUSPARSE_OPERATION_NON_TRANSPOSE, &one, m.d, x.d, &zero, y.d, CUDA_R_64F,
                                kSpmvAlg, &bytes),
        "cusparseSpMV_bufferSize");
  if (bytes > buffer.size()) buffer = DeviceArray<char>(bytes);
  check(cusparseSpMV(handle, CUSPARSE_OPERATION_NON_TRANSPOSE, &one, m.d, x.d, &zero, y.d, CUDA_R_64F,
                     kSpmvAlg, buffer.get()),
        "cusparseSpMV");
}

void spmv(cusparseHandle_t handle, const DeviceCsr& m, const double* x, double* y, DeviceArray<char>& buffer) {
  const SpMat mat(m);
  const DnVec vx(m.cols, const_cast<double*>(x)), vy(m.rows, y);
  spmv(handle, mat, vx, vy, buffer);
}

CusparseAssembly assemble_cusparse(const CsrView& a, std::span<const double> b) {
  if (b.size() != size_t(a.rows) || a.row_ptr.size() != size_t(a.rows) + 1 || a.col.size() != a.val.size())
    throw std::invalid_argument("assemble_cusparse: sizes of A and b do not match");
  require_device("cuda-normal-equations");
  CusparseAssembly out;
  SparseHandle handle;
  auto t0 = std::chrono::steady_clock::now();
  const DeviceCsr da = upload_csr(a);
  DeviceArray<double> db(b.data(), b.size());
  check(cudaDeviceSynchronize(), "upload");
  out.upload_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();

  EventTimer timer;
  timer.start();
  const DeviceCsr at = transpose(handle, da);
  const DeviceCsr c = spgemm_ata(handle, at, da);
  DeviceArray<double> atb(size_t(a.cols));
  DeviceArray<char> buffer;
  if (a.rows > 0) spmv(handle, at, db.get(), atb.get(), buffer);
  else check(cudaMemset(atb.get(), 0, atb.size() * sizeof(double)), "cudaMemset");
  out.assemble_ms = timer.stop();

  out.row_ptr = c.row_ptr.download();
  out.col = c.col.download();
  out.val = c.val.download();
  out.atb = atb.download();
  return out;
}

}  // namespace tfm::cuda
