// FMA throughput of one and of two threads at once (16 independent AVX-512 chains each). Used for
// NOTES.md: the two virtual CPUs do not share FMA units. Build and run:
//   gcc -O2 -mavx512f -mfma -pthread fma-threads.c -o fma-threads && ./fma-threads 1 && ./fma-threads 2
#include <immintrin.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
static double now(){struct timespec t;clock_gettime(CLOCK_MONOTONIC,&t);return t.tv_sec+t.tv_nsec*1e-9;}
static long ITERS=200000000;
void* run(void*arg){
  __m512 a0=_mm512_setzero_ps(),a1=a0,a2=a0,a3=a0,a4=a0,a5=a0,a6=a0,a7=a0,a8=a0,a9=a0,a10=a0,a11=a0,a12=a0,a13=a0,a14=a0,a15=a0;
  __m512 m=_mm512_set1_ps(1.0000001f),c=_mm512_set1_ps(1e-7f);
  for(long i=0;i<ITERS;i++){
    __asm__ volatile(
    "vfmadd231ps %[m],%[c],%[a0]\n vfmadd231ps %[m],%[c],%[a1]\n vfmadd231ps %[m],%[c],%[a2]\n vfmadd231ps %[m],%[c],%[a3]\n"
    "vfmadd231ps %[m],%[c],%[a4]\n vfmadd231ps %[m],%[c],%[a5]\n vfmadd231ps %[m],%[c],%[a6]\n vfmadd231ps %[m],%[c],%[a7]\n"
    :[a0]"+v"(a0),[a1]"+v"(a1),[a2]"+v"(a2),[a3]"+v"(a3),[a4]"+v"(a4),[a5]"+v"(a5),[a6]"+v"(a6),[a7]"+v"(a7)
    :[m]"v"(m),[c]"v"(c));
    __asm__ volatile(
    "vfmadd231ps %[m],%[c],%[a8]\n vfmadd231ps %[m],%[c],%[a9]\n vfmadd231ps %[m],%[c],%[a10]\n vfmadd231ps %[m],%[c],%[a11]\n"
    "vfmadd231ps %[m],%[c],%[a12]\n vfmadd231ps %[m],%[c],%[a13]\n vfmadd231ps %[m],%[c],%[a14]\n vfmadd231ps %[m],%[c],%[a15]\n"
    :[a8]"+v"(a8),[a9]"+v"(a9),[a10]"+v"(a10),[a11]"+v"(a11),[a12]"+v"(a12),[a13]"+v"(a13),[a14]"+v"(a14),[a15]"+v"(a15)
    :[m]"v"(m),[c]"v"(c));
  }
  float out[16]; _mm512_storeu_ps(out,_mm512_add_ps(a0,a15)); if(out[0]==1234.f) printf("x");
  return 0;
}
int main(int argc,char**argv){
  int n=atoi(argv[1]);
  pthread_t t[4]; double s=now();
  for(int i=0;i<n;i++) pthread_create(&t[i],0,run,0);
  for(int i=0;i<n;i++) pthread_join(t[i],0);
  double e=now()-s;
  printf("threads %d: %.1f GFLOP/s total\n", n, n*ITERS*16.0*16*2/e/1e9);
}
