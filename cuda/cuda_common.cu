// Device discovery, the CSR transposition and the channel reductions shared by the CUDA paths.
#include "tfmatch/cuda/cuda_common.cuh"

namespace tfm::cuda {

bool device_available(std::string* why) {
  int count = 0;
  const cudaError_t e = cudaGetDeviceCount(&count);
  if (e != cudaSuccess || count == 0) {
    if (why) *why = e != cudaSuccess ? cudaGetErrorString(e) : "0 devices";
    return false;
  }
  return true;
}

void require_device(const std::string& who) {
  std::string why;
  if (!device_available(&why)) throw std::runtime_error(who + ": no CUDA device available (cudaGetDeviceCount: " + why + ")");
  check(cudaSetDevice(0), "cudaSetDevice");
}

std::string device_name() {
  cudaDeviceProp prop{};
  if (!device_available() || cudaGetDeviceProperties(&prop, 0) != cudaSuccess) return "no CUDA device";
  return prop.name;
}

namespace {

__global__ void squared_norm_partials(const double* q, uint64_t len, double* partials) {
  __shared__ double sh[kReduceThreads];
  double acc = 0.0;
  for (uint64_t i = uint64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < len; i += uint64_t(gridDim.x) * blockDim.x)
    acc += q[i] * q[i];
  double tot[4];
  reduce_channels(acc, sh, tot);
  if (threadIdx.x < 4) partials[4 * blockIdx.x + threadIdx.x] = tot[threadIdx.x];
}

}  // namespace

void launch_squared_norm_partials(const double* q, uint64_t len, double* partials) {
  squared_norm_partials<<<kPartialBlocks, kReduceThreads>>>(q, len, partials);
}

std::array<double, 4> squared_norms_per_channel(const double* q, uint64_t len) {
  DeviceArray<double> partials(4 * size_t(kPartialBlocks));
  launch_squared_norm_partials(q, len, partials.get());
  check(cudaGetLastError(), "squared_norm_partials");
  const std::vector<double> host = partials.download();
  std::array<double, 4> out{};
  for (int b = 0; b < kPartialBlocks; ++b)
    for (int c = 0; c < 4; ++c) out[size_t(c)] += host[4 * size_t(b) + size_t(c)];
  return out;
}

DeviceCsr transpose(cusparseHandle_t handle, const DeviceCsr& a) {
  DeviceCsr t;
  t.rows = a.cols;
  t.cols = a.rows;
  t.nnz = a.nnz;
  t.row_ptr = DeviceArray<int>(size_t(a.cols) + 1);
  t.col = DeviceArray<int>(size_t(a.nnz));
  t.val = DeviceArray<double>(size_t(a.nnz));
  if (a.nnz == 0) {
    check(cudaMemset(t.row_ptr.get(), 0, (size_t(a.cols) + 1) * sizeof(int)), "cudaMemset");
    return t;
  }
  size_t bytes = 0;
  check(cusparseCsr2cscEx2_bufferSize(handle, a.rows, a.cols, int(a.nnz), a.val.get(), a.row_ptr.get(), a.col.get(),
                                      t.val.get(), t.row_ptr.get(), t.col.get(), CUDA_R_64F, CUSPARSE_ACTION_NUMERIC,
                                      CUSPARSE_INDEX_BASE_ZERO, CUSPARSE_CSR2CSC_ALG1, &bytes),
        "cusparseCsr2cscEx2_bufferSize");
  DeviceArray<char> buffer(bytes);
  check(cusparseCsr2cscEx2(handle, a.rows, a.cols, int(a.nnz), a.val.get(), a.row_ptr.get(), a.col.get(), t.val.get(),
                           t.row_ptr.get(), t.col.get(), CUDA_R_64F, CUSPARSE_ACTION_NUMERIC, CUSPARSE_INDEX_BASE_ZERO,
                           CUSPARSE_CSR2CSC_ALG1, buffer.get()),
        "cusparseCsr2cscEx2");
  return t;
}

SpMat::SpMat(const DeviceCsr& m) {
  check(cusparseCreateCsr(&d, m.rows, m.cols, m.nnz, m.row_ptr.get(), m.col.get(), m.val.get(), CUSPARSE_INDEX_32I,
                          CUSPARSE_INDEX_32I, CUSPARSE_INDEX_BASE_ZERO, CUDA_R_64F),
        "cusparseCreateCsr");
}

SpMat::SpMat(int64_t rows, int64_t cols) {
  check(cusparseCreateCsr(&d, rows, cols, 0, nullptr, nullptr, nullptr, CUSPARSE_INDEX_32I, CUSPARSE_INDEX_32I,
                          CUSPARSE_INDEX_BASE_ZERO, CUDA_R_64F),
        "cusparseCreateCsr");
}

// CSR algorithm 2, the one for row-major dense matrices. Run-to-run bits matter here (the default
// SpMV on A^T's long rows changed them on an H100); CglsIsBitIdenticalAndHonoursTheCap and
// NormalEquationsMatchExactSolution check them on a CUDA device.
constexpr cusparseSpMMAlg_t kSpmmAlg = CUSPARSE_SPMM_CSR_ALG2;

void spmm(cusparseHandle_t handle, const SpMat& m, const DnMat& x, const DnMat& y, DeviceArray<char>& buffer) {
  const double one = 1.0, zero = 0.0;
  const cusparseOperation_t op = CUSPARSE_OPERATION_NON_TRANSPOSE;
  size_t bytes = 0;
  check(cusparseSpMM_bufferSize(handle, op, op, &one, m.d, x.d, &zero, y.d, CUDA_R_64F, kSpmmAlg,
                                &bytes),
        "cusparseSpMM_bufferSize");
  if (bytes > buffer.size()) buffer = DeviceArray<char>(bytes);
  check(cusparseSpMM(handle, op, op, &one, m.d, x.d, &zero, y.d, CUDA_R_64F, kSpmmAlg, buffer.get()),
        "cusparseSpMM");
}

}  // namespace tfm::cuda
